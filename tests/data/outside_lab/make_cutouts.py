import numpy as np
from scipy.interpolate import CubicSpline
from astropy.io import fits
rng = np.random.default_rng(16)
DISP = 120.2423285104674
def cut(ps, name):
    a = np.loadtxt(f'/tmp/outside2/lsf_truth/lsf115_{ps}/lsf.csv', delimiter=',', skiprows=1)
    f = CubicSpline(a[:, 0], a[:, 1])
    pix = np.arange(25) - 12            # pixel index relative to the line pixel
    prof = f((pix - 0.3)*18.0); prof = prof/prof.max()
    illum = np.linspace(0.8, 1.2, 9)
    img = np.array([rng.poisson(12000*w*prof + 300) + rng.normal(0, 8, prof.size) for w in illum]).T  # (NAXIS2=25, NAXIS1=9)
    h = fits.PrimaryHDU(np.round(img).astype('i4'))
    h.header['CTYPE1'] = 'LINEAR'; h.header['CUNIT1'] = 'pixel'; h.header['CRPIX1'] = 1; h.header['CRVAL1'] = 0; h.header['CDELT1'] = 1
    h.header['CTYPE2'] = 'WAVE'; h.header['CUNIT2'] = 'nm'; h.header['CRPIX2'] = 13.0; h.header['CRVAL2'] = 1250.0
    h.header['CDELT2'] = -18.0/DISP; h.header['BUNIT'] = 'adu'; h.header['OBJECT'] = f'arc J {ps}mas'
    h.writeto(name, overwrite=True, output_verify='silentfix')
cut(250, 'J_250mas_cutout.fits'); cut(25, 'J_25mas_cutout.fits')
