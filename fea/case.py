"""One FEA case: every model parameter with its unit, default and valid range, in one place.

Units: µm for film thickness, mm for geometry and element sizes, K for temperatures,
fractions for polish.

:class:`FEACase` is the flat set of scalars a study config, a sweep, the API and a
diagnosis manifest give (``t0_um = 200``, ``substrate = "AlSi40"``, ``pitch_x_mm = 42``);
:data:`PARAMETERS` describes each of them. :meth:`FEACase.from_params` checks a mapping
before any meshing: unknown names (with a did-you-mean), types, choices, the ranges of
the model objects (:class:`fea.geometry.Blank`, :class:`fea.coating.Coating`,
:class:`fea.mesh.MeshSpec`, :class:`fea.model.ThermalLoad`, the materials' data range),
the caps of a physically sane grating blank and the memory the mesh will need
(:mod:`fea.mesh_budget`). Every refusal is a :class:`fea.errors.ParameterError` whose
``parameter`` is the case's own key. :meth:`FEACase.to_objects` builds what the solver
takes; :meth:`FEACase.cache_key` names the case's result in a cache.

Example
-------
>>> case = FEACase.from_params({"t0_um": 150, "polish": 0.5})
>>> case.to_objects().coating.polish_back
0.5
>>> FEACase.from_params({"t0_mu": 150})
Traceback (most recent call last):
...
fea.errors.ParameterError: unknown FEA parameter(s) ['t0_mu']; did you mean 't0_um'? valid names are [...]
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace

from .calibration import STRESS_SCALE
from .coating import COVERAGES, Coating
from .errors import ParameterError
from .geometry import Blank
from .materials import MATERIALS, Material
from .mesh import MeshSpec
from .mesh_budget import check_mesh_budget
from .model import ThermalLoad

__all__ = ["Parameter", "PARAMETERS", "FEACase", "CaseObjects", "resolve_params", "model_namespace",
           "mesh_spec_for"]


@dataclass(frozen=True)
class Parameter:
    """One FEA parameter.

    Parameters
    ----------
    name : str
    kind : {"float", "int", "str"}
    unit : str
        ``""`` for dimensionless values and names.
    default : object
        ``None`` = the model's own default (see ``doc``).
    doc : str
        What it is.
    valid : str
        The valid values or range, in words (shown in errors and the config example).
    low, high : float, optional
        Bounds of the cap :meth:`FEACase.from_params` enforces itself (the objects enforce
        the rest of ``valid``); ``low_open`` makes the lower bound exclusive.
    choices : tuple of str
        The only valid values of a ``str`` parameter.
    """

    name: str
    kind: str
    unit: str
    default: object
    doc: str
    valid: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    choices: tuple[str, ...] = ()

    @property
    def bounds_text(self) -> str:
        """``low``/``high`` in interval notation, e.g. ``"[10, 1000]"`` or ``"> 0"``."""
        if self.low is not None and self.high is not None:
            return f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}]"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {self.low:g}"
        return "" if self.high is None else f"<= {self.high:g}"

    def check_range(self, value) -> None:
        """Raise :class:`ParameterError` if ``value`` is outside ``low``/``high``."""
        if value is None or self.kind == "str":
            return
        below = self.low is not None and (value <= self.low if self.low_open else value < self.low)
        if below or (self.high is not None and value > self.high):
            unit = f" {self.unit}" if self.unit else ""
            raise ParameterError(self.name, value, f"{self.name}={value!r} is outside the valid range "
                                                   f"{self.bounds_text}{unit} ({self.doc})")


_MATERIAL_NAMES = tuple(sorted(MATERIALS))
#: the model objects' own defaults (the paper's blank, coating and cool-down)
_DEFAULT = {f.name: f.default for cls in (Blank, Coating, ThermalLoad) for f in fields(cls)}
_GEOMETRY = "a physically sane grating blank"
#: Every FEA parameter, in the order of cache keys and tables. Ranges of the blank are the
#: caps of a grating blank (a 1 km blank or a 0.01 mm hole is a unit mistake, and would
#: mesh for ever); the objects add their cross-checks (holes inside the blank, walls).
PARAMETERS: dict[str, Parameter] = {p.name: p for p in (
    Parameter("coverage", "str", "", "all", "which surfaces carry NiP (Table 1: all; Table 2: holes, surfaces)",
              f"one of {', '.join(COVERAGES)}", choices=COVERAGES),
    Parameter("t0_um", "float", "µm", _DEFAULT["t0_um"], "as-plated NiP thickness", "(0, 2000]"),
    Parameter("polish", "float", "", _DEFAULT["polish_front"], "fraction of t0 left on both faces after polishing", "(0, 1]"),
    Parameter("polish_back", "float", "", None, "fraction of t0 left on the back face (default: as the front)",
              "(0, 1]"),
    Parameter("cold_K", "float", "K", _DEFAULT["cold_K"], "operating temperature", "4..300 (material data range)"),
    Parameter("warm_K", "float", "K", _DEFAULT["warm_K"], "temperature at which the blank is stress-free",
              "4..300 (material data range)"),
    Parameter("substrate", "str", "", "Al6061-T6", "blank material", f"one of {', '.join(_MATERIAL_NAMES)}",
              choices=_MATERIAL_NAMES),
    Parameter("film", "str", "", "NiP", "plating material", f"one of {', '.join(_MATERIAL_NAMES)}",
              choices=_MATERIAL_NAMES),
    Parameter("stress_scale", "float", "", None, f"film mismatch-stress multiplier (default: calibrated "
              f"{STRESS_SCALE:g}; 1 = nominal material data)", "> 0", low=0.0, low_open=True),
    Parameter("size_x_mm", "float", "mm", _DEFAULT["size_x_mm"], "blank extent along x (dispersion)",
              f"10..1000 ({_GEOMETRY}); holes must not overlap nor break through a face", 10.0, 1000.0),
    Parameter("size_y_mm", "float", "mm", _DEFAULT["size_y_mm"], "blank extent along y (grooves)",
              f"10..1000 ({_GEOMETRY}); holes must not overlap nor break through a face", 10.0, 1000.0),
    Parameter("thickness_mm", "float", "mm", _DEFAULT["thickness_mm"], "blank thickness along z",
              f"2..300 ({_GEOMETRY}); holes must not overlap nor break through a face", 2.0, 300.0),
    Parameter("hole_diameter_mm", "float", "mm", _DEFAULT["hole_diameter_mm"], "diameter of every lightweighting hole",
              "1..300; holes must not overlap nor break through a face", 1.0, 300.0),
    Parameter("pitch_x_mm", "float", "mm", _DEFAULT["pitch_x_mm"], "spacing in x of the holes drilled along y",
              "> 0 and <= 1000; holes must not overlap nor break through a face", 0.0, 1000.0, True),
    Parameter("n_holes_x", "int", "", _DEFAULT["n_holes_x"], "number of holes drilled along y (0 = none)",
              "integer 0..100; holes must stay inside the blank", 0, 100),
    Parameter("pitch_y_mm", "float", "mm", _DEFAULT["pitch_y_mm"], "spacing in y of the holes drilled along x",
              "> 0 and <= 1000; holes must not overlap nor break through a face", 0.0, 1000.0, True),
    Parameter("n_holes_y", "int", "", _DEFAULT["n_holes_y"], "number of holes drilled along x (0 = none)",
              "integer 0..100; holes must stay inside the blank", 0, 100),
    Parameter("hole_axis_z_mm", "float", "mm", _DEFAULT["hole_axis_z_mm"], "z of the hole axes (0 = mid-plane)",
              "any; the holes must keep 0.5 mm walls to both faces"),
    Parameter("mesh_size_mm", "float", "mm", None, "element size near the faces and hole walls (default 1.4)",
              "> 0 and <= thickness_mm; the mesh must fit the memory budget"),
    Parameter("mesh_bulk_mm", "float", "mm", None, "element size in the bulk (default 2.8)",
              ">= mesh_size_mm and <= the blank's larger side"),
)}

_BLANK_KEYS = tuple(f.name for f in fields(Blank))
#: field of a model object -> the case's key, where they differ
_FIELD_TO_KEY = {"polish_front": "polish", "size_mm": "mesh_size_mm", "size_bulk_mm": "mesh_bulk_mm"}


def _closest(name: str, names) -> str:
    match = difflib.get_close_matches(str(name), list(names), n=1, cutoff=0.5)
    return f"; did you mean {match[0]!r}?" if match else ""


def _coerce(p: Parameter, value):
    """``value`` as the parameter's type, or ParameterError naming it (None stays None)."""
    if value is None:
        if p.default is None:
            return None
        raise ParameterError(p.name, value, f"{p.name}=None: give a value ({p.valid})")
    if p.kind == "str":
        if not isinstance(value, str):
            raise ParameterError(p.name, value, f"{p.name}={value!r} must be a string ({p.valid})")
        if p.choices and value not in p.choices:
            raise ParameterError(p.name, value, f"{p.name}={value!r} is unknown; valid values are "
                                                f"{list(p.choices) if p.name == 'coverage' else sorted(p.choices)}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) and not hasattr(value, "__float__"):
        raise ParameterError(p.name, value, f"{p.name}={value!r} must be a number ({p.valid})")
    if not math.isfinite(float(value)):
        raise ParameterError(p.name, value, f"{p.name}={value!r} must be finite ({p.valid})")
    if p.kind == "int":
        if float(value) != int(value):
            raise ParameterError(p.name, value, f"{p.name}={value!r} must be an integer ({p.valid})")
        return int(value)
    return float(value)


def resolve_params(params: Mapping) -> dict:
    """Every parameter's effective value (defaults filled in, ``None`` resolved), unchecked.

    ``polish_back`` None -> ``polish``; ``stress_scale`` None -> the calibrated scale; mesh
    sizes None -> :class:`fea.mesh.MeshSpec`'s. Unknown keys are kept at the end.
    """
    full = {k: p.default for k, p in PARAMETERS.items()}
    full.update(params)
    if full["polish_back"] is None:
        full["polish_back"] = full["polish"]
    if full["stress_scale"] is None:
        full["stress_scale"] = STRESS_SCALE
    if full["mesh_size_mm"] is None:
        full["mesh_size_mm"] = MeshSpec().size_mm
    if full["mesh_bulk_mm"] is None:
        full["mesh_bulk_mm"] = MeshSpec().size_bulk_mm
    return full


def mesh_spec_for(coating: Coating, spec: MeshSpec | None = None, blank: Blank | None = None) -> MeshSpec:
    """The mesh spec to use: eighth model when the film and the blank are symmetric about
    the mid-plane, quarter model otherwise (front and back polish differ, or the holes are
    off the mid-plane)."""
    spec = spec or MeshSpec()
    symmetric = coating.is_z_symmetric and (blank is None or blank.is_z_symmetric)
    if not symmetric and spec.symmetry == "eighth":
        spec = replace(spec, symmetry="quarter")
    return spec


def model_namespace() -> str:
    """Cache namespace of FEA results: the solver's physics version and the calibration
    (a cached result must not survive either changing)."""
    from . import MODEL_VERSION

    return f"fea-v{MODEL_VERSION}-scale{STRESS_SCALE:.8g}"


@dataclass(frozen=True)
class CaseObjects:
    """What the solver takes for one case (see :meth:`FEACase.to_objects`)."""

    blank: Blank
    mesh: MeshSpec
    coating: Coating
    load: ThermalLoad
    substrate: Material
    film: Material
    stress_scale: float


def _field(name: str):
    """A case field: default and metadata (``metadata["parameter"]``) from :data:`PARAMETERS`."""
    return field(default=PARAMETERS[name].default, metadata={"parameter": PARAMETERS[name]})


@dataclass(frozen=True)
class FEACase:
    """One FEA case; each field's unit, default and range are its :data:`PARAMETERS` entry
    (also ``dataclasses.fields(FEACase)[i].metadata["parameter"]``).

    Build it with :meth:`from_params` (which checks everything); the constructor stores
    what it is given. ``None`` in ``polish_back``, ``stress_scale``, ``mesh_size_mm``,
    ``mesh_bulk_mm`` means the model's default (:func:`resolve_params`).
    """

    coverage: str = _field("coverage")
    t0_um: float = _field("t0_um")
    polish: float = _field("polish")
    polish_back: float | None = _field("polish_back")
    cold_K: float = _field("cold_K")
    warm_K: float = _field("warm_K")
    substrate: str = _field("substrate")
    film: str = _field("film")
    stress_scale: float | None = _field("stress_scale")
    size_x_mm: float = _field("size_x_mm")
    size_y_mm: float = _field("size_y_mm")
    thickness_mm: float = _field("thickness_mm")
    hole_diameter_mm: float = _field("hole_diameter_mm")
    pitch_x_mm: float = _field("pitch_x_mm")
    n_holes_x: int = _field("n_holes_x")
    pitch_y_mm: float = _field("pitch_y_mm")
    n_holes_y: int = _field("n_holes_y")
    hole_axis_z_mm: float = _field("hole_axis_z_mm")
    mesh_size_mm: float | None = _field("mesh_size_mm")
    mesh_bulk_mm: float | None = _field("mesh_bulk_mm")

    @classmethod
    def from_params(cls, params: Mapping, *, memory_budget_bytes: float | None = None,
                    check_memory: bool = True) -> FEACase:
        """The case of a flat mapping of parameter values, checked before any meshing.

        Parameters
        ----------
        params : mapping
            Parameter name (:data:`PARAMETERS`) -> value; missing ones take their default.
        memory_budget_bytes : float, optional
            Memory the mesh may need (default: a share of this machine's memory, see
            :func:`fea.mesh_budget.memory_budget_bytes`).
        check_memory : bool
            Estimate the mesh's memory (skip when a prepared model is reused).

        Raises
        ------
        ParameterError
            A ``ValueError`` naming the parameter (``.parameter`` is the key of ``params``),
            the value and the valid range.
        """
        unknown = sorted(set(params) - set(PARAMETERS))
        if unknown:
            hint = _closest(unknown[0], PARAMETERS)
            raise ParameterError(unknown[0], params[unknown[0]], f"unknown FEA parameter(s) {unknown}"
                                 f"{hint + ' ' if hint else '; '}valid names are {sorted(PARAMETERS)}")
        case = cls(**{k: _coerce(PARAMETERS[k], v) for k, v in params.items()})
        case.check(memory_budget_bytes=memory_budget_bytes, check_memory=check_memory)
        return case

    def check(self, *, memory_budget_bytes: float | None = None, check_memory: bool = True) -> None:
        """Run the case through the materials' data range, the model objects, the caps and
        the memory budget (:meth:`from_params` does; see there)."""
        for p in PARAMETERS.values():  # also for a case built with the constructor
            _coerce(p, getattr(self, p.name))
        for mat in ("substrate", "film"):  # the material's data range first: the most specific message
            for t in ("cold_K", "warm_K"):
                MATERIALS[getattr(self, mat)].check_temperature(getattr(self, t), t)
        if self.stress_scale is not None:
            PARAMETERS["stress_scale"].check_range(self.stress_scale)
        try:
            objects = self.to_objects()
        except ParameterError as exc:
            key = _FIELD_TO_KEY.get(exc.parameter, exc.parameter)
            msg = str(exc)
            for f, k in _FIELD_TO_KEY.items():  # the message names the keys the user wrote
                msg = re.sub(rf"\b{f}=", f"{k}=", msg)
            raise ParameterError(key, exc.value, msg) from None
        for name in _BLANK_KEYS:
            PARAMETERS[name].check_range(getattr(self, name))
        blank, spec = objects.blank, objects.mesh
        if spec.size_mm > blank.thickness_mm:
            raise ParameterError("mesh_size_mm", spec.size_mm, f"mesh_size_mm={spec.size_mm:g} is larger than "
                                 f"the blank's thickness_mm={blank.thickness_mm:g}; valid range is "
                                 f"0 < mesh_size_mm <= thickness_mm")
        longest = max(blank.size_x_mm, blank.size_y_mm)
        if spec.size_bulk_mm > longest:
            raise ParameterError("mesh_bulk_mm", spec.size_bulk_mm, f"mesh_bulk_mm={spec.size_bulk_mm:g} is "
                                 f"larger than the blank ({longest:g} mm); valid range is "
                                 f"mesh_size_mm <= mesh_bulk_mm <= {longest:g} mm")
        if check_memory:
            check_mesh_budget(blank, spec, memory_budget_bytes)

    def to_objects(self, mesh: MeshSpec | None = None) -> CaseObjects:
        """The blank, mesh spec, coating, thermal load, materials and stress scale of the case.

        The mesh is the eighth model when film and blank are symmetric about the mid-plane,
        the quarter model otherwise. ``mesh`` replaces the case's element sizes (its
        symmetry is kept unless the case needs the quarter model).
        """
        blank = Blank(**{k: getattr(self, k) for k in _BLANK_KEYS})
        polish_back = self.polish if self.polish_back is None else self.polish_back
        coating = Coating(t0_um=self.t0_um, polish_front=self.polish, polish_back=polish_back,
                          coverage=self.coverage)
        if mesh is None:
            sizes = {k: v for k, v in (("size_mm", self.mesh_size_mm), ("size_bulk_mm", self.mesh_bulk_mm))
                     if v is not None}
            mesh = replace(MeshSpec(), **sizes)  # one replace: the sizes are validated together
        mesh = mesh_spec_for(coating, mesh, blank)
        load = ThermalLoad(warm_K=self.warm_K, cold_K=self.cold_K)
        scale = STRESS_SCALE if self.stress_scale is None else self.stress_scale
        return CaseObjects(blank, mesh, coating, load, MATERIALS[self.substrate], MATERIALS[self.film], scale)

    def as_params(self) -> dict:
        """Every parameter -> value, in :data:`PARAMETERS` order (``from_params`` round-trips it)."""
        return asdict(self)

    def resolved(self) -> FEACase:
        """The same case with every ``None`` replaced by the value it stands for."""
        return replace(self, **{k: v for k, v in resolve_params(self.as_params()).items()})

    def cache_key(self) -> str:
        """Hex digest naming this case's result: the solver's namespace and the resolved
        parameters, so two spellings of one case (default given or not) share it."""
        text = json.dumps({"namespace": model_namespace(), "params": self.resolved().as_params()}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:20]
