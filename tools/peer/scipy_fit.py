#!/usr/bin/env python3
"""A SciPy speed peer for brdfd's fits of the paper's spectral Cook–Torrance/GGX model.

What it measures
----------------
For every scan file and every cost function (cf1, cf2, m2) it

1. runs ``BRDFD fit --input SCAN --cost CF --json`` and reads brdfd's cost, fitted
   parameters, ``wall_ms`` and SRA reading model (``sra``) from the JSON;
2. computes the scan's measured BRDF from the scan file as SCIENCE.md §3 says
   (``M = S / W / π`` against the Munsell N9 reference with ρ_ref = 1, ``M = S / π`` for
   "instrument-calibration" scans; the SRA value ``q = I / I_ref`` spread flat over the 31
   bands, ``M = q / π``, the ``ratio`` strategy);
3. evaluates the same 34-parameter model (kd ×31, ks, α, μ; Schlick Fresnel on cos θi, GGX D,
   Smith–Walter G, SCIENCE.md §4) at brdfd's parameters and checks that its cost equals
   brdfd's reported cost to 1e-9 relative (the peer fits the same problem);
4. fits the model with a multi-start ``scipy.optimize.least_squares`` (method "trf", bounds
   kd ∈ [0, 1], ks ∈ [0, 10], α ∈ [0.01, 1], μ ∈ [1, 3], analytic Jacobian, ``x_scale="jac"``,
   ftol = xtol = gtol = 1e-10, at most 2000 evaluations per start, one BLAS thread) and times
   the whole multi-start with ``time.perf_counter``.

The cost functions are written as least-squares residuals ρ with Σρ² = cost², N the number of
(geometry, band) terms (14·31 = 434, or 12·31 = 372 without SRA readings), w = cos θi:

* cf1: ρ = (w·M − w·A) / √N.
* cf2: Σ|r|^(2/3) with r = w·M − w·A, i.e. ρ = sign(r)·|r|^(1/3) / √N. That residual has an
  infinite slope at r = 0, so the fit minimises the smoothed ρ = r·(r² + ε²)^(−1/3) / √N with
  ε = 1e-7 (ρ² → |r|^(2/3) as ε → 0; ρ' = (r²/3 + ε²)(r² + ε²)^(−4/3) is finite). The cost
  reported is always the exact cf2 (ε = 0) at the returned parameters.
* m2: ρ = (ln(1 + w·M) − ln(1 + w·A)) / √N.

SRA reading model (SCIENCE.md §5.1): the one brdfd's fit reports in its JSON. ``flat``: the SRA
spectra enter like any other, 31 residuals per geometry. ``luminance`` (illuminant C, 2° ȳ, the
only instrument this script carries tables for): one residual per SRA geometry on
``w·Y(M) − w·Y(A)``, ``Y(f) = Σ c_b f_b``, ``c_b = C(λ_b) ȳ(λ_b) / Σ C ȳ``, scaled by √31.

Multi-start: ``--starts`` (default 8) seeded starts (``--seed``, default 1): ks log-uniform in
[1e-3, 10], α log-uniform in [0.01, 1], μ uniform in [1, 3]; kd per band the median over the
four back-scatter MA-T12 geometries (15as45, 15as80, 45as75, 45as110, far from any specular
peak) of the measured BRDF, clipped into (0, 1). The best cost of the starts is reported.

Output: one line per scan and cost function (brdfd's and the peer's cost, times and the
model check), then a Markdown table per kind of scan ("synthetic": scans with SRA readings,
"real": scans without) and cost function: median brdfd fit ms
(its ``wall_ms``), median peer ms, the ratio peer/brdfd, and on how many scans the peer's best
cost is within 1 % of brdfd's and which is lower.

How to run (python3 with numpy and scipy)
-----------------------------------------
::

    B=/path/to/brdfd
    $B synth --out /tmp/peer/synth
    $B import-format tests/data/real-mat12/*.xlsx --out /tmp/peer/real
    python3 tools/peer/scipy_fit.py --brdfd $B /tmp/peer/synth/*.scan.json /tmp/peer/real/*.scan.json

``--json FILE`` also writes every row as JSON; ``--fit-args "--sra flat"`` (or ``"--method paper"``)
passes more arguments to ``brdfd fit``, the peer then fitting under the SRA model brdfd reports.
"""

import os

# The fit is a small dense problem: one BLAS thread (more only contend on a shared machine).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import shlex  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

BANDS = 31
MA_T12_COUNT = 12

# (name, θi, θr, φr) in SCIENCE.md §2 table order.
GEOMETRIES = [
    ("15as-45", 60, 15, 180),
    ("15as-30", 45, 15, 180),
    ("15as-15", 30, 15, 180),
    ("15as15", 0, 15, 180),
    ("15as45", 30, 15, 0),
    ("15as80", 65, 15, 0),
    ("45as-15", 60, 45, 180),
    ("45as15", 30, 45, 180),
    ("45as25", 20, 45, 180),
    ("45as45", 0, 45, 180),
    ("45as75", 30, 45, 0),
    ("45as110", 65, 45, 0),
    ("sra-20", 20, 20, 180),
    ("sra-60", 60, 60, 180),
]
BACKSCATTER = ["15as45", "15as80", "45as75", "45as110"]

# CIE illuminant C (CIE 15:2004 Table T.1) and the CIE 1931 2° ȳ at 400, 410, …, 700 nm.
ILLUMINANT_C = np.array([
    63.3, 80.6, 98.1, 112.4, 121.5, 124.0, 123.1, 123.8, 123.9, 120.7, 112.1, 102.3, 96.9,
    98.0, 102.1, 105.2, 105.3, 102.3, 97.8, 93.2, 89.7, 88.4, 88.1, 88.0, 87.8, 88.2, 87.9,
    86.3, 84.0, 80.2, 76.3,
])
YBAR_2DEG = np.array([
    0.000396, 0.00121, 0.004, 0.0116, 0.023, 0.038, 0.06, 0.09098, 0.13902, 0.20802, 0.323,
    0.503, 0.71, 0.862, 0.954, 0.9949501, 0.995, 0.952, 0.87, 0.757, 0.631, 0.503, 0.381,
    0.265, 0.175, 0.107, 0.061, 0.032, 0.017, 0.00821, 0.004102,
])
LUM_C2 = ILLUMINANT_C * YBAR_2DEG / np.sum(ILLUMINANT_C * YBAR_2DEG)

BOUNDS_LO = np.concatenate([np.zeros(BANDS), [0.0, 0.01, 1.0]])
BOUNDS_HI = np.concatenate([np.ones(BANDS), [10.0, 1.0, 3.0]])
CF2_EPS = 1e-7


def _direction(theta, phi):
    t, p = math.radians(theta), math.radians(phi)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


class Geometry:
    """The angles of a subset of the 14 geometries, as arrays over that subset."""

    def __init__(self, names):
        rows = [g for g in GEOMETRIES if g[0] in names]
        l = np.array([_direction(ti, 0.0) for _, ti, _, _ in rows])
        v = np.array([_direction(tr, pr) for _, _, tr, pr in rows])
        s = l + v
        h = s / np.sqrt(np.sum(s * s, axis=1))[:, None]
        self.names = [g[0] for g in rows]
        self.cos_i = l[:, 2]
        self.cos_r = v[:, 2]
        self.cos_h = h[:, 2]
        self.l_dot_h = np.sum(l * h, axis=1)
        self.v_dot_h = np.sum(v * h, axis=1)
        self.w = np.array([math.cos(math.radians(ti)) for _, ti, _, _ in rows])
        self.is_sra = np.array([n.startswith("sra-") for n in self.names])


def _g1(alpha, cos_x, x_dot_h):
    c2 = cos_x * cos_x
    tan2 = (1.0 - c2) / c2
    chi = (x_dot_h / cos_x > 0.0).astype(float)
    return np.where(cos_x > 0.0, chi * 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2)), 0.0)


def specular(geo, ks, alpha, ior):
    """``ks·F·D·G / (π cosθi cosθr)`` per geometry (SCIENCE.md §4, Schlick on cos θi)."""
    r = (1.0 - ior) / (1.0 + ior)
    f0 = r * r
    f = f0 + (1.0 - f0) * (1.0 - geo.cos_i) ** 5
    a2 = alpha * alpha
    c2 = geo.cos_h * geo.cos_h
    tan2 = (1.0 - c2) / c2
    s = a2 + tan2
    d = np.where(geo.cos_h > 0.0, a2 / (math.pi * c2 * c2 * s * s), 0.0)
    g = _g1(alpha, geo.cos_i, geo.l_dot_h) * _g1(alpha, geo.cos_r, geo.v_dot_h)
    return ks * f * d * g / (math.pi * geo.cos_i * geo.cos_r)


def specular_grad(geo, ks, alpha, ior):
    """d specular / d(ks, α, μ), shape (geometries, 3): ks exact, α and μ by central differences."""
    out = np.empty((len(geo.names), 3))
    out[:, 0] = specular(geo, 1.0, alpha, ior)
    for j, (x, lo, hi) in enumerate(((alpha, 0.01, 1.0), (ior, 1.0, 3.0)), start=1):
        h = 1e-6 * max(1.0, abs(x))
        xp, xm = min(x + h, hi), max(x - h, lo)
        args_p = (ks, xp, ior) if j == 1 else (ks, alpha, xp)
        args_m = (ks, xm, ior) if j == 1 else (ks, alpha, xm)
        out[:, j] = (specular(geo, *args_p) - specular(geo, *args_m)) / (xp - xm)
    return out


class Problem:
    """The measured BRDF of one scan and the residuals of one cost function on it."""

    def __init__(self, measured, cost, sra_model):
        self.geo = Geometry(list(measured))
        self.M = np.array([measured[n] for n in self.geo.names])  # (G, 31)
        self.cost_name = cost
        self.sra_luminance = sra_model == "luminance" and bool(self.geo.is_sra.any())
        self.n_terms = self.M.size
        self.spec_rows = ~self.geo.is_sra if self.sra_luminance else np.ones(len(self.geo.names), bool)
        w = self.geo.w
        self.wM_spec = (self.M * w[:, None])[self.spec_rows].ravel()
        self.w_spec = np.repeat(w[self.spec_rows], BANDS)
        self.band_spec = np.tile(np.arange(BANDS), int(self.spec_rows.sum()))
        self.geo_spec = np.repeat(np.nonzero(self.spec_rows)[0], BANDS)
        if self.sra_luminance:
            lum_idx = np.nonzero(~self.spec_rows)[0]
            self.lum_idx = lum_idx
            self.wYM = (self.M[lum_idx] @ LUM_C2) * w[lum_idx]
            self.w_lum = w[lum_idx]
        self.scale = 1.0 / math.sqrt(self.n_terms)

    def model(self, x):
        return x[None, :BANDS] + specular(self.geo, *x[BANDS:])[:, None]

    def _phi(self, m, a, eps):
        """Residual transform and its derivative with respect to a."""
        if self.cost_name == "cf1":
            return m - a, -np.ones_like(a)
        if self.cost_name == "m2":
            return np.log1p(m) - np.log1p(a), -1.0 / (1.0 + a)
        r = m - a
        q = r * r + eps * eps
        if eps == 0.0:
            return np.sign(r) * np.abs(r) ** (1.0 / 3.0), None
        return r * q ** (-1.0 / 3.0), -(r * r / 3.0 + eps * eps) * q ** (-4.0 / 3.0)

    def residuals(self, x, eps=CF2_EPS):
        A = self.model(x)
        wA = (A * self.geo.w[:, None])[self.spec_rows].ravel()
        res, _ = self._phi(self.wM_spec, wA, eps)
        if self.sra_luminance:
            wYA = (A[self.lum_idx] @ LUM_C2) * self.w_lum
            r2, _ = self._phi(self.wYM, wYA, eps)
            res = np.concatenate([res, math.sqrt(BANDS) * r2])
        return res * self.scale

    def jacobian(self, x, eps=CF2_EPS):
        A = self.model(x)
        ds = specular_grad(self.geo, *x[BANDS:])  # (G, 3)
        wA = (A * self.geo.w[:, None])[self.spec_rows].ravel()
        _, dphi = self._phi(self.wM_spec, wA, eps)
        k = dphi * self.w_spec  # d residual / d A
        n_rows = k.size + (len(self.lum_idx) if self.sra_luminance else 0)
        J = np.zeros((n_rows, BANDS + 3))
        rows = np.arange(k.size)
        J[rows, self.band_spec] = k
        J[: k.size, BANDS:] = k[:, None] * ds[self.geo_spec]
        if self.sra_luminance:
            wYA = (A[self.lum_idx] @ LUM_C2) * self.w_lum
            _, dl = self._phi(self.wYM, wYA, eps)
            kl = math.sqrt(BANDS) * dl * self.w_lum  # d residual / d Y(A)
            J[k.size :, :BANDS] = kl[:, None] * LUM_C2[None, :]
            J[k.size :, BANDS:] = kl[:, None] * ds[self.lum_idx]  # Σ c_b = 1
        return J * self.scale

    def cost(self, x):
        """The exact cost function (ε = 0) at x."""
        r = self.residuals(np.asarray(x, float), eps=0.0)
        return math.sqrt(float(np.sum(r * r)))

    def kd_start(self):
        idx = [self.geo.names.index(n) for n in BACKSCATTER if n in self.geo.names]
        return np.clip(np.median(self.M[idx], axis=0), 1e-6, 1.0 - 1e-6)


def measured_brdf(scan):
    """Measured BRDF per geometry name (SCIENCE.md §3, ρ_ref = 1, ratio strategy)."""
    out = {}
    ref = scan.get("reference")
    ma = scan["readings"]["ma_t12"]
    for name, s in ma.items():
        s = np.asarray(s, float)
        if isinstance(ref, dict):
            out[name] = s / np.asarray(ref["ma_t12"][name], float) / math.pi
        else:
            out[name] = s / math.pi
    sra = scan["readings"].get("sra")
    if isinstance(sra, dict):
        for name, i in sra.items():
            q = float(i) / float(ref["sra"][name])
            out[name] = np.full(BANDS, q / math.pi)
    return out


def run_brdfd(brdfd, scan_path, cost, extra):
    out = subprocess.run(
        [brdfd, "fit", "--input", scan_path, "--cost", cost, "--json", *extra],
        check=True, capture_output=True, text=True,
    ).stdout
    return json.loads(out)


def peer_fit(problem, starts, seed):
    rng = np.random.default_rng(seed)
    kd0 = problem.kd_start()
    best_cost, best_x, nfev = math.inf, None, 0
    t0 = time.perf_counter()
    for _ in range(starts):
        ks = 10 ** rng.uniform(-3.0, 1.0)
        alpha = 10 ** rng.uniform(-2.0, 0.0)
        ior = rng.uniform(1.0, 3.0)
        x0 = np.concatenate([kd0, [ks, alpha, ior]])
        x0 = np.clip(x0, BOUNDS_LO + 1e-9, BOUNDS_HI - 1e-9)
        sol = least_squares(
            problem.residuals, x0, jac=problem.jacobian, bounds=(BOUNDS_LO, BOUNDS_HI),
            method="trf", x_scale="jac", ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=2000,
        )
        nfev += sol.nfev
        c = problem.cost(sol.x)
        if c < best_cost:
            best_cost, best_x = c, sol.x
    wall_ms = (time.perf_counter() - t0) * 1e3
    return best_cost, best_x, wall_ms, nfev


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--brdfd", required=True, help="path of the brdfd binary")
    ap.add_argument("scans", nargs="+", help="brdfd.scan/1 files")
    ap.add_argument("--costs", default="cf1,cf2,m2")
    ap.add_argument("--starts", type=int, default=8)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", help="also write every row as JSON to this file")
    ap.add_argument(
        "--fit-args", default="",
        help='more arguments for "brdfd fit", e.g. "--sra flat" or "--method paper" (the model must stay the paper\'s)',
    )
    args = ap.parse_args()

    rows, bad = [], 0
    for path in args.scans:
        with open(path) as fh:
            scan = json.load(fh)
        measured = measured_brdf(scan)
        kind = "synthetic" if len(measured) == 14 else "real"
        for cf in args.costs.split(","):
            fit = run_brdfd(args.brdfd, path, cf, shlex.split(args.fit_args))
            sra = fit.get("sra", {})
            if len(measured) == 14 and sra.get("model") == "luminance":
                if (sra.get("illuminant"), sra.get("observer")) != ("C", "2"):
                    sys.exit(f"{path}: SRA instrument {sra} has no table here (only C, 2°)")
            if fit.get("fresnel", "incidence") != "incidence" or fit.get("model", "paper") != "paper":
                sys.exit(f"{path}: brdfd fitted another model than the paper's: {fit.get('model')}, {fit.get('fresnel')}")
            problem = Problem(measured, cf, sra.get("model", "flat"))
            p = fit["params"]
            xb = np.concatenate([p["kd"], [p["ks"], p["alpha"], p["ior"]]])
            check = problem.cost(xb)
            rel = abs(check - fit["cost"]) / abs(fit["cost"]) if fit["cost"] else abs(check)
            ok = rel <= 1e-9
            bad += not ok
            cost, x, ms, nfev = peer_fit(problem, args.starts, args.seed)
            row = dict(
                scan=path, sample=scan.get("sample"), kind=kind, cost_function=cf,
                sra=sra.get("model") if len(measured) == 14 else None,
                brdfd_cost=fit["cost"], brdfd_ms=fit["wall_ms"], brdfd_evaluations=fit.get("evaluations"),
                model_check_cost=check, model_check_rel=rel, model_check_ok=ok,
                peer_cost=cost, peer_ms=ms, peer_nfev=nfev,
                peer_params=dict(ks=x[BANDS], alpha=x[BANDS + 1], ior=x[BANDS + 2]),
                brdfd_params=dict(ks=p["ks"], alpha=p["alpha"], ior=p["ior"]),
            )
            rows.append(row)
            print(
                f"{kind:9} {cf:3} {str(scan.get('sample')):22} brdfd {fit['cost']:.9e} {fit['wall_ms']:8.2f} ms"
                f" | peer {cost:.9e} {ms:9.1f} ms nfev {nfev:5d} | model check rel {rel:.1e} {'ok' if ok else 'FAIL'}",
                flush=True,
            )

    print()
    for kind in ("synthetic", "real"):
        sel = [r for r in rows if r["kind"] == kind]
        if not sel:
            continue
        print(f"### {kind} scans ({len({r['scan'] for r in sel})})\n")
        print("| cost | median brdfd fit ms | median peer ms | peer/brdfd | peer within 1 % of brdfd | lower cost (brdfd / peer / tie < 1e-9) |")
        print("|---|---|---|---|---|---|")
        for cf in args.costs.split(","):
            rs = [r for r in sel if r["cost_function"] == cf]
            if not rs:
                continue
            bm = statistics.median(r["brdfd_ms"] for r in rs)
            pm = statistics.median(r["peer_ms"] for r in rs)
            within = sum(abs(r["peer_cost"] - r["brdfd_cost"]) <= 0.01 * r["brdfd_cost"] for r in rs)
            tie = lambda r: abs(r["peer_cost"] - r["brdfd_cost"]) <= 1e-9 * max(r["brdfd_cost"], 1e-300)
            b_low = sum(r["brdfd_cost"] < r["peer_cost"] and not tie(r) for r in rs)
            p_low = sum(r["peer_cost"] < r["brdfd_cost"] and not tie(r) for r in rs)
            ties = len(rs) - b_low - p_low
            print(f"| {cf} | {bm:.2f} | {pm:.1f} | {pm / bm:.0f}× | {within}/{len(rs)} | {b_low} / {p_low} / {ties} |")
        print()
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    if bad:
        sys.exit(f"{bad} model check(s) failed: the peer's cost at brdfd's parameters differs from brdfd's")


if __name__ == "__main__":
    main()
