"""brdfd from Python: scans, instrument exports, spectral BRDF fits, the model and the store.

Every number is computed by the brdfd Rust library (the native module ``brdfd._native``): a fit
from here is the fit ``brdfd fit --json`` prints for the same scan and options, to the last bit.
This module only turns those numbers into Python, numpy, pandas and colour-science values.
"""

from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import Scan

__all__ = [
    "Scan",
    "FitResult",
    "Store",
    "read_scan",
    "import_export",
    "fit",
    "crossval",
    "evaluate",
    "geometries",
    "wavelengths",
    "WAVELENGTHS",
    "GEOMETRIES",
]

__version__: str = _native.VERSION

#: The model's band centres, nm (400–700 every 10 nm).
WAVELENGTHS: np.ndarray = np.array(_native.wavelengths(), dtype=np.int64)

#: The 14 geometries in table order, as dicts (name, device, theta_i, theta_r, phi_r, aspecular).
GEOMETRIES: List[Dict[str, Any]] = [
    dict(zip(("name", "device", "theta_i", "theta_r", "phi_r", "aspecular"), g))
    for g in _native.geometries()
]


def geometries() -> List[str]:
    """The 14 geometry names in table order (12 MA-T12 ones, then the SRA's two)."""
    return _geometry_names()


def _geometry_names() -> List[str]:
    return [g["name"] for g in GEOMETRIES]


def wavelengths() -> np.ndarray:
    """The model's band centres, nm."""
    return WAVELENGTHS.copy()


def read_scan(path: Union[str, "os.PathLike[str]"]) -> Scan:
    """Reads a ``brdfd.scan/1`` file."""
    return _native.read_scan(str(path))


def import_export(
    path: Union[str, "os.PathLike[str]"],
    sra: Optional[Union[str, "os.PathLike[str]"]] = None,
    reference: Optional[str] = None,
) -> List[Scan]:
    """Reads an instrument's export as ``brdfd import-format`` does.

    X-Rite's QC ``.xlsx`` export (one scan per measurement, reference "instrument
    calibration", no SRA readings), the MA-T12's CGATS or CxF3 export (``sra``: the SRA's CSV
    when the file has no SRA values; ``reference``: the object that is the white tile,
    default "Munsell N9"), or a brdfd export in any format.  The colorimetry check of an
    ``.xlsx`` import is on each scan's ``colorimetry_check`` in :func:`import_export_checked`.
    """
    return [scan for scan, _ in import_export_checked(path, sra, reference)]


def import_export_checked(
    path: Union[str, "os.PathLike[str]"],
    sra: Optional[Union[str, "os.PathLike[str]"]] = None,
    reference: Optional[str] = None,
) -> List[Tuple[Scan, Optional[Dict[str, Any]]]]:
    """:func:`import_export`, each scan with the colorimetry check of an X-Rite export
    (``{"largest_delta_e00", "at", "warning"}``; ``None`` for other formats)."""
    pairs = _native.import_export(str(path), None if sra is None else str(sra), reference)
    return [(scan, None if check is None else json.loads(check)) for scan, check in pairs]


@dataclass(frozen=True)
class FitResult:
    """A finished fit: the fit document of ``brdfd fit --json`` and its numbers as arrays.

    ``document`` is that JSON object as Python values (floats to the last bit); the other
    fields are views of it: ``params`` (``kd`` as a 31-value array, ``ks``, ``alpha``,
    ``ior``), ``delta_e00`` (per geometry measured), ``lab`` (per geometry, measured and fitted
    L*a*b* arrays), ``intervals`` (95 % bootstrap intervals, ``None`` without ``bootstrap``).
    """

    document: Dict[str, Any]
    params: Dict[str, Any]
    delta_e00: Dict[str, float]
    lab: Dict[str, Dict[str, np.ndarray]]
    intervals: Optional[Dict[str, Any]]
    measured: np.ndarray = field(repr=False)
    estimated: np.ndarray = field(repr=False)
    _json: str = field(repr=False)

    @property
    def delta_e00_mean(self) -> float:
        return self.document["delta_e00_mean"]

    @property
    def cost(self) -> float:
        """The cost function's value at the fitted parameters (``document["cost"]``)."""
        return self.document["cost"]

    @property
    def geometries(self) -> List[str]:
        """The geometries measured, in table order (14, or 12 without SRA readings)."""
        return list(self.delta_e00)

    def to_json(self) -> str:
        """The fit document exactly as ``brdfd fit --json`` prints it."""
        return self._json

    def evaluate(self, geometries: Optional[Sequence[Any]] = None,
                 wavelengths: Optional[Sequence[int]] = None) -> np.ndarray:
        """The fitted model's BRDF (sr⁻¹) with this fit's parameters and Fresnel cosine."""
        return evaluate(self.params, geometries, wavelengths, fresnel=self.document["fresnel"],
                        model=self.document.get("model", "paper"))

    def reflectance(self, geometry: str, which: str = "measured") -> np.ndarray:
        """The reflectance factor π·f at one geometry, 31 bands: ``which`` is ``"measured"`` or
        ``"fitted"`` (the columns ``measured`` and ``estimated_<cost>`` of the tidy export)."""
        names = _geometry_names()
        if geometry not in names:
            raise ValueError(f"unknown geometry {geometry!r}; valid: {', '.join(names)}")
        i = names.index(geometry)
        if which == "measured":
            row = self.measured[i]
            if np.isnan(row).all():
                raise ValueError(f"the scan has no reading at {geometry}")
        elif which == "fitted":
            row = self.estimated[i]
        else:
            raise ValueError(f"which={which!r}; valid: 'measured', 'fitted'")
        return np.pi * row

    def spectral_distribution(self, geometry: str, which: str = "measured") -> Any:
        """:meth:`reflectance` as a ``colour.SpectralDistribution`` (needs colour-science)."""
        return to_spectral_distribution(
            self.reflectance(geometry, which),
            name=f"{self.document['sample']} {geometry} {which}",
        )


def to_spectral_distribution(values: Sequence[float], wavelengths: Optional[Sequence[int]] = None,
                             name: Optional[str] = None) -> Any:
    """Values at the model's bands (or ``wavelengths``) as a ``colour.SpectralDistribution``."""
    try:
        import colour
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "colour-science is not installed: `pip install colour-science` (or brdfd[colour])"
        ) from e
    wl = WAVELENGTHS if wavelengths is None else np.asarray(wavelengths)
    return colour.SpectralDistribution(dict(zip(wl.tolist(), np.asarray(values, float).tolist())),
                                       name=name)


def fit(
    scan: Scan,
    cost: str = "cf2",
    method: Optional[str] = None,
    seed: Optional[int] = None,
    bootstrap: int = 0,
    sra: Optional[str] = None,
    *,
    specular: Optional[str] = None,
    fresnel: Optional[str] = None,
    observer: Optional[str] = None,
    weighting: Optional[str] = None,
    sra_illuminant: Optional[str] = None,
    sra_observer: Optional[str] = None,
    model: Optional[str] = None,
    hold_out: Optional[Sequence[str]] = None,
    preset: Optional[str] = None,
    sra_weight: Optional[str] = None,
) -> FitResult:
    """Fits a scan as ``brdfd fit`` does with the same options (``cost``: cf1, cf2, m2;
    ``method``: the default or "paper"; ``bootstrap``: resamples for 95 % intervals, 0 skips
    them; ``preset``: "measured" (the default: exact Fresnel, luminance SRA) or "paper" (the
    paper's configuration: Schlick on cos θi, flat SRA), whose choices ``model`` ("paper",
    "oren-nayar" or "two-lobe"), ``fresnel`` ("exact", "incidence" or "light-half") and ``sra``
    ("luminance" or "flat") and ``sra_weight`` ("balanced" or "paper": how much the SRA
    readings weigh beside the MA-T12's; the measured preset balances them under cf1 and m2)
    override one by one;
    ``hold_out``: MA-T12 geometries left out of the fit and predicted, as ``brdfd fit
    --hold-out``: their predictions are ``document["held_out"]``).  Runs without holding the
    GIL."""
    report = _native.fit(
        scan, cost, method, seed, bootstrap, sra, specular=specular, fresnel=fresnel,
        observer=observer, weighting=weighting, sra_illuminant=sra_illuminant,
        sra_observer=sra_observer, model=model,
        hold_out=None if hold_out is None else list(hold_out), preset=preset,
        sra_weight=sra_weight,
    )
    text = report.to_json()
    doc = json.loads(text)
    p = doc["params"]
    # The paper's parameters, and a model option's own (sigma, ks2, alpha2) when it has them.
    params = {k: (np.array(v, dtype=float) if k == "kd" else v) for k, v in p.items()}
    lab = {g: {"measured": np.array(v["measured"], dtype=float),
               "fitted": np.array(v["fitted"], dtype=float),
               "residual": v.get("residual")} for g, v in doc["lab"].items()}
    unc = doc.get("uncertainty")
    intervals = None
    if unc is not None:
        # Numeric lists become arrays; "at_bound" (parameter names) stays a list.
        intervals = {k: (np.array(v, dtype=float)
                         if isinstance(v, list) and not any(isinstance(x, str) for x in v)
                         else v)
                     for k, v in unc.items()}
    measured = np.array([[np.nan] * len(WAVELENGTHS) if m is None else m
                         for m in report.measured()], dtype=float)
    return FitResult(
        document=doc,
        params=params,
        delta_e00=dict(doc["delta_e00"]),
        lab=lab,
        intervals=intervals,
        measured=measured,
        estimated=np.array(report.estimated(), dtype=float),
        _json=text,
    )


def crossval(
    scan: Scan,
    cost: Optional[Union[str, Sequence[str]]] = None,
    *,
    model: Optional[str] = None,
    fresnel: Optional[str] = None,
    method: Optional[str] = None,
    seed: Optional[int] = None,
    sra: Optional[str] = None,
    observer: Optional[str] = None,
    weighting: Optional[str] = None,
    preset: Optional[str] = None,
    sra_weight: Optional[str] = None,
) -> Dict[str, Any]:
    """Leave-one-geometry-out cross-validation as ``brdfd crossval --json`` makes it with the
    same options: each MA-T12 geometry held out of the fit in turn and predicted. ``cost``: one
    cost function or several (all three when ``None``); ``preset``, ``model``, ``fresnel``,
    ``sra`` and ``sra_weight`` as in :func:`fit`. Returns that JSON object as Python
    values: ``{"sample", "reference", "fits": [{"cost", "model", "fresnel", "fitted_mean",
    "held_out_mean", "held_out": [{"geometry", "delta_e00", "measured_lab",
    "predicted_lab", "predicted_l_interval"}, …]}, …]}`` (the last the 95 % interval of the
    held-out L*).  Runs without holding the GIL."""
    costs = [cost] if isinstance(cost, str) else (None if cost is None else list(cost))
    text = _native.crossval(scan, costs, model=model, fresnel=fresnel, method=method, seed=seed,
                            sra=sra, observer=observer, weighting=weighting, preset=preset,
                            sra_weight=sra_weight)
    return json.loads(text)


def evaluate(
    params: Union[Dict[str, Any], FitResult],
    geometries: Optional[Sequence[Any]] = None,
    wavelengths: Optional[Sequence[int]] = None,
    fresnel: str = "incidence",
    model: str = "paper",
) -> np.ndarray:
    """The model's BRDF (sr⁻¹), shape (len(geometries), len(wavelengths)).

    ``params``: ``{"kd": 31 values, "ks", "alpha", "ior"}``, with a model option's own
    parameters (``"sigma"`` for ``oren-nayar``, ``"ks2"`` and ``"alpha2"`` for ``two-lobe``),
    or a :class:`FitResult` (then its Fresnel cosine and model option).  ``geometries``: names
    (default: all 14) or ``(θi, θr, φr)`` tuples in degrees.  ``wavelengths``: band centres in
    nm (default: all 31; the model has no values between bands).  ``model``: the model option
    (SCIENCE.md §4.1), the paper's by default.
    """
    if isinstance(params, FitResult):
        return params.evaluate(geometries, wavelengths)
    extra_names = {"paper": [], "oren-nayar": ["sigma"], "two-lobe": ["ks2", "alpha2"]}
    if model not in extra_names:
        raise ValueError(f"unknown model {model!r}; valid: {', '.join(extra_names)}")
    missing = [n for n in extra_names[model] if n not in params]
    if missing:
        raise ValueError(f"model {model!r} needs the parameters {', '.join(missing)}")
    extra = [float(params[n]) for n in extra_names[model]]
    geos = [g if isinstance(g, str) else tuple(float(a) for a in g)
            for g in (_geometry_names() if geometries is None else geometries)]
    wl = WAVELENGTHS.tolist() if wavelengths is None else [int(w) for w in wavelengths]
    rows = _native.evaluate([float(k) for k in params["kd"]], float(params["ks"]),
                            float(params["alpha"]), float(params["ior"]), geos, wl, fresnel,
                            model, extra)
    return np.array(rows, dtype=float).reshape(len(geos), len(wl))


def _rows(text: str) -> Any:
    """A tidy CSV table as a pandas DataFrame, or a list of dicts (numbers as float, empty
    cells as None) without pandas."""
    try:
        import pandas as pd
    except ImportError:
        out = []
        for row in csv.DictReader(io.StringIO(text)):
            out.append({k: _cell(v) for k, v in row.items()})
        return out
    return pd.read_csv(io.StringIO(text), float_precision="round_trip",
                       dtype={"reason": "string", "station": "string"})


def _cell(v: str) -> Any:
    if v == "":
        return None
    try:
        return int(v)
    except ValueError:
        pass
    try:
        return float(v)
    except ValueError:
        return v


class Store:
    """A brdfd store (SQLite), opened read-only for each read: works beside a running daemon
    and never migrates or locks it.  ``scans()`` and ``fits()`` are the two tables of the tidy
    export (``brdfd export-format --format tidy``), row for row."""

    def __init__(self, path: Union[str, "os.PathLike[str]"], include_simulated: bool = True):
        self.path = str(path)
        self.include_simulated = include_simulated

    def _tables(self) -> Tuple[str, str]:
        return _native.store_tidy(self.path, self.include_simulated)

    def scans(self) -> Any:
        """spectra.csv: one row per scan × geometry × band."""
        return _rows(self._tables()[0])

    def fits(self) -> Any:
        """fits.csv: one row per scan × cost function."""
        return _rows(self._tables()[1])

    def __repr__(self) -> str:
        return f"Store({self.path!r})"

