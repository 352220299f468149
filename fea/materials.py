"""Material data: elastic constants and integrated thermal strain, with sources.

Units: SI for moduli (Pa), kelvin for temperatures, thermal strain dimensionless
(ΔL/L relative to 293 K).

Thermal strain is what the FEA needs, not a CTE: the film/substrate mismatch strain
between two temperatures is ``ε_film(T) − ε_substrate(T)`` minus the same at the
reference temperature, integrated exactly through the cryogenic fall-off of the CTE.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import ParameterError

__all__ = ["Material", "AL6061_T6", "NIP_HIGH_P", "ALSI40", "MATERIALS", "get_material"]

T_REF_K = 293.0

# NIST cryogenic material properties, 6061-T6 aluminium, linear expansion
# (L - L293)/L293 * 1e5 = a + bT + cT^2 + dT^3 + eT^4, valid 4-300 K
# (https://trc.nist.gov/cryogenics/materials/6061%20Aluminum/6061_T6Aluminum_rev.htm).
_NIST_AL6061_COEFFS = (-4.1277e02, -3.0389e-01, 8.7696e-03, -9.9821e-06, 0.0)


def _nist_al6061_strain(temperature_K: np.ndarray) -> np.ndarray:
    T = np.asarray(temperature_K, dtype=float)
    a, b, c, d, e = _NIST_AL6061_COEFFS
    return 1e-5 * (a + b * T + c * T**2 + d * T**3 + e * T**4)


# Shift so that the curve is exactly zero at 293 K (NIST's fit leaves -7e-7 there).
_AL_OFFSET = float(_nist_al6061_strain(T_REF_K))
#: Room-temperature CTE of 6061-T6 from the derivative of the NIST fit at 293 K (1/K).
AL6061_CTE_293K = 1e-5 * float(
    _NIST_AL6061_COEFFS[1]
    + 2 * _NIST_AL6061_COEFFS[2] * T_REF_K
    + 3 * _NIST_AL6061_COEFFS[3] * T_REF_K**2
)


@dataclass(frozen=True)
class Material:
    """An isotropic linear-elastic material with a tabulated thermal strain.

    Parameters
    ----------
    name : str
        Short identifier (used in configs and cache keys).
    youngs_modulus_Pa : float
        Young's modulus (Pa).
    poisson_ratio : float
        Poisson ratio, in (-1, 0.5).
    cte_293K_per_K : float
        Room-temperature coefficient of thermal expansion (1/K), informative and
        used to scale the reference curve for materials without a cryogenic fit.
    strain_scale : float
        Thermal strain of this material is ``strain_scale`` times the 6061-T6 NIST
        curve (1.0 for 6061 itself). Debye-like materials share the shape of the
        CTE fall-off to a good approximation; the scale is the RT CTE ratio.
    valid_range_K : (float, float)
        Temperatures for which the thermal-strain data are valid.
    source : str
        Where the numbers come from and how uncertain they are.
    """

    name: str
    youngs_modulus_Pa: float
    poisson_ratio: float
    cte_293K_per_K: float
    strain_scale: float = 1.0
    valid_range_K: tuple[float, float] = (4.0, 300.0)
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not 1e8 <= self.youngs_modulus_Pa <= 1e13:
            raise ValueError(
                f"Material {self.name!r}: youngs_modulus_Pa={self.youngs_modulus_Pa:g} is outside the "
                "plausible range 1e8..1e13 Pa (did you pass GPa?)"
            )
        if not -1.0 < self.poisson_ratio < 0.5:
            raise ValueError(
                f"Material {self.name!r}: poisson_ratio={self.poisson_ratio} must lie in (-1, 0.5)"
            )
        if not self.strain_scale >= 0:
            raise ValueError(f"Material {self.name!r}: strain_scale={self.strain_scale} must be >= 0")

    def check_temperature(self, temperature_K: float, parameter: str = "temperature_K") -> None:
        """Raise ValueError if ``temperature_K`` is outside the material data's range."""
        lo, hi = self.valid_range_K
        if not (lo <= temperature_K <= hi):
            raise ParameterError(
                parameter, temperature_K,
                f"{parameter}={temperature_K} K is outside the thermal-strain data range of "
                f"{self.name} ({lo:g}..{hi:g} K)"
            )

    def thermal_strain(self, temperature_K: float | np.ndarray) -> np.ndarray:
        """Integrated thermal strain ΔL/L relative to 293 K (dimensionless, negative when cold)."""
        T = np.asarray(temperature_K, dtype=float)
        return self.strain_scale * (_nist_al6061_strain(T) - _AL_OFFSET)

    def strain_between(self, warm_K: float, cold_K: float) -> float:
        """Thermal strain accumulated from ``warm_K`` to ``cold_K`` (dimensionless)."""
        self.check_temperature(warm_K, "warm_K")
        self.check_temperature(cold_K, "cold_K")
        return float(self.thermal_strain(cold_K) - self.thermal_strain(warm_K))

    @classmethod
    def with_al6061_shape(cls, name: str, youngs_modulus_Pa: float, poisson_ratio: float,
                          cte_293K_per_K: float, source: str) -> Material:
        """A material without a cryogenic expansion curve of its own: the 6061-T6 NIST
        curve scaled by the ratio of the room-temperature CTEs (``strain_scale``)."""
        return cls(name=name, youngs_modulus_Pa=youngs_modulus_Pa, poisson_ratio=poisson_ratio,
                   cte_293K_per_K=cte_293K_per_K, strain_scale=cte_293K_per_K / AL6061_CTE_293K, source=source)

    @property
    def lame_mu_Pa(self) -> float:
        return self.youngs_modulus_Pa / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lame_lambda_Pa(self) -> float:
        E, nu = self.youngs_modulus_Pa, self.poisson_ratio
        return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))

    @property
    def biaxial_modulus_Pa(self) -> float:
        """E/(1−ν): the stress per unit equal-biaxial strain of a thin film."""
        return self.youngs_modulus_Pa / (1.0 - self.poisson_ratio)


AL6061_T6 = Material(
    name="Al6061-T6",
    youngs_modulus_Pa=68.9e9,
    poisson_ratio=0.33,
    cte_293K_per_K=AL6061_CTE_293K,
    strain_scale=1.0,
    source=(
        "E, nu: ASM Aerospace Specification Metals / MIL-HDBK-5 (68.9 GPa, 0.33, room temperature; "
        "E rises ~8 % at 80 K, not modelled: the calibrated film stress absorbs a common scale). "
        "Thermal strain: NIST cryogenic fit for 6061-T6, -0.386 % from 293 K to 80 K, "
        "uncertainty ~2 % of the integrated value."
    ),
)

NIP_HIGH_P = Material.with_al6061_shape(
    name="NiP",
    youngs_modulus_Pa=60e9,
    poisson_ratio=0.33,
    cte_293K_per_K=13.0e-6,
    source=(
        "Electroless nickel, high phosphorus (10-13 wt% P), as plated (amorphous). "
        "E = 60 GPa: supplier data sheets give 50-70 GPa (7-10 Mpsi) for high-P deposits, "
        "nanoindentation papers 100-200 GPa; the spread is real (porosity, heat treatment). "
        "60 GPa is the data-sheet mid value; with it the model's thickness nonlinearity "
        "P/V(200 um)/P/V(100 um) is 1.86/1.82/1.82 for polish 100/75/50 % against the paper's "
        "1.88/1.83/1.86 (default mesh). nu = 0.33 (data-sheet range 0.3-0.4). "
        "CTE 13e-6/K at room temperature (data sheets 11-14e-6/K); no cryogenic curve is "
        "published, so the 6061 NIST shape is scaled by the RT CTE ratio (0.575): "
        "-0.222 % from 293 K to 80 K, uncertain by ~30 %. The film mismatch stress is therefore "
        "the one calibrated constant of the model (fea.calibration)."
    ),
)

ALSI40 = Material.with_al6061_shape(
    name="AlSi40",
    youngs_modulus_Pa=92e9,
    poisson_ratio=0.28,
    cte_293K_per_K=13.5e-6,
    source=(
        "Spray-formed hypereutectic AlSi40 (e.g. RSP/Dispal S221 class; Kinast et al. 2014): "
        "E ~ 92 GPa, nu ~ 0.28, CTE ~ 13.5e-6/K at RT, matched to NiP within 0.5e-6/K as the "
        "paper states. Cryogenic curve: 6061 NIST shape scaled by the RT CTE ratio."
    ),
)

MATERIALS: dict[str, Material] = {m.name: m for m in (AL6061_T6, NIP_HIGH_P, ALSI40)}


def get_material(name: str | Material) -> Material:
    """Look up a material by name (or pass a Material through)."""
    if isinstance(name, Material):
        return name
    try:
        return MATERIALS[name]
    except KeyError:
        raise ValueError(f"material={name!r} is unknown; valid names are {sorted(MATERIALS)}") from None
