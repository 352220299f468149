# Line profiles, lab-like, from the toolkit's own nominal J LSFs (cryograting lsf ... --sag nominal_80K.npz)
import numpy as np, csv
from scipy.interpolate import CubicSpline
rng = np.random.default_rng(11)
def load(ps):
    a = np.loadtxt(f"/tmp/outside/nominal/lsf_J_{ps}/lsf.csv", delimiter=",", skiprows=1)
    return a[:, 0], a[:, 1]
def box(off, I, w):
    """convolve with a box of full width w (um) on the 1 um grid"""
    n = int(round(w)); k = np.ones(n + 1); k[0] = k[-1] = 0.5; k /= k.sum()
    return np.convolve(I, k, mode="same")
def lab(off, I, shift, step, lo, hi, peak=40000., ped=1500., read=15.):
    f = CubicSpline(off, I)
    o = np.arange(lo, hi + 1e-9, step) + rng.uniform(-0.2, 0.2)       # another grid, its own origin
    p = f(o - shift)                                                    # line centred at +shift
    p = p / p.max() * peak
    cts = rng.poisson(p + ped).astype(float) + rng.normal(0, read, o.size)
    return o, cts
for case, w in (("l1_nominal_counts", 0.0), ("l2_slit_box18", 18.0)):
    d = "/tmp/outside/cases/" + case
    # 250 mas: CSV with preamble, offset_um + Flux [ADU] (pedestal kept), 1.5 um steps
    off, I = load(250); I = box(off, I, w) if w else I
    o, c = lab(off, I, 2.3, 1.5, -120, 120)
    with open(f"{d}/J_1p25_250mas.csv", "w") as f:
        f.write("SPIFFI lab test, J grating, 1.25 um arc line, 250 mas\nDate: 2026-11-30  Exposure: 30 s\n")
        f.write("offset_um,Flux [ADU]\n")
        for a, b in zip(o, c): f.write(f"{a:.3f},{b:.1f}\n")
    # 100 mas: semicolon-delimited, decimal commas, background-subtracted (negative samples), 2 um steps
    off, I = load(100); I = box(off, I, w) if w else I
    o, c = lab(off, I, -1.7, 2.0, -110, 110)
    c = c - 1500.0
    with open(f"{d}/J_1p25_100mas.csv", "w") as f:
        f.write("Offset [um];Intensity [counts]\n")
        for a, b in zip(o, c): f.write(f"{a:.3f};{b:.1f}".replace(".", ",") + "\n")
    # 25 mas: offsets in detector pixels (dithered by 1/8 px), whitespace, numpy savetxt header
    off, I = load(25); I = box(off, I, w) if w else I
    o, c = lab(off, I, 0.9, 18 / 8, -100, 100, peak=25000)
    np.savetxt(f"{d}/J_1p25_25mas.txt", np.c_[o / 18.0, c], header="offset_px counts", fmt="%.5f")
    print(case, "min counts 100mas", c.min())
