"""The Python package against the brdfd binary: the same fits to the last bit, the same tidy
rows, the model's numbers, and the numpy / pandas / colour-science forms of them.

Needs the brdfd binary of the same source tree: BRDFD_BIN (default: brdfd on PATH)."""

from __future__ import annotations

import json
import math
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import brdfd

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data"
SCAN = DATA / "t-sky-blue.noisy.scan.json"
XLSX = DATA / "real-mat12" / "PAR_PW_RO_NG_1.xlsx"


def brdfd_bin() -> str:
    path = os.environ.get("BRDFD_BIN") or shutil.which("brdfd")
    if not path:
        pytest.fail("set BRDFD_BIN to the brdfd binary of this source tree (target/release/brdfd)")
    return path


def run(*args: str) -> str:
    out = subprocess.run([brdfd_bin(), *args], check=True, capture_output=True, text=True)
    return out.stdout


def same_bits(a, b, path="$"):
    """a == b, floats compared by their IEEE-754 bits (so -0.0 ≠ 0.0 and NaN == NaN)."""
    if isinstance(a, float) or isinstance(b, float):
        assert isinstance(a, float) and isinstance(b, float), f"{path}: {a!r} vs {b!r}"
        assert struct.pack("<d", a) == struct.pack("<d", b), f"{path}: {a!r} vs {b!r}"
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), f"{path}: keys {list(a)} vs {list(b)}"
        for k in a:
            same_bits(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: lengths differ"
        for i, (x, y) in enumerate(zip(a, b)):
            same_bits(x, y, f"{path}[{i}]")
    else:
        assert a == b and type(a) is type(b), f"{path}: {a!r} vs {b!r}"


def without_timing(doc: dict) -> dict:
    doc = dict(doc)
    assert isinstance(doc.pop("wall_ms"), float)
    return doc


def test_fit_equals_the_cli_bit_for_bit():
    scan = brdfd.read_scan(SCAN)
    got = brdfd.fit(scan, cost="cf2", seed=7)
    cli = json.loads(run("fit", "--input", str(SCAN), "--cost", "cf2", "--seed", "7", "--json"))
    same_bits(without_timing(got.document), without_timing(cli))
    # The text too, but for the timing: the same shortest round-trip numbers.
    strip = lambda t: json.dumps(without_timing(json.loads(t)))  # noqa: E731
    assert strip(got.to_json()) == strip(json.dumps(cli))


def test_fit_with_options_and_bootstrap_equals_the_cli():
    scan = brdfd.read_scan(SCAN)
    got = brdfd.fit(scan, cost="m2", method="paper", seed=3, bootstrap=4, sra="luminance")
    cli = json.loads(run("fit", "--input", str(SCAN), "--cost", "m2", "--method", "paper",
                         "--seed", "3", "--bootstrap", "4", "--sra", "luminance", "--json"))
    same_bits(without_timing(got.document), without_timing(cli))
    iv = got.intervals
    assert iv is not None and iv["resamples"] == 4
    for name in ("ks", "alpha", "ior"):
        lo, hi = iv[name]
        assert lo <= hi
    assert iv["kd"].shape == (31, 2)
    assert (iv["kd"][:, 0] <= iv["kd"][:, 1]).all()


def test_the_preset_gives_the_clis_defaults_bit_for_bit():
    scan = brdfd.read_scan(SCAN)
    # The default, as for the CLI: the measured preset (exact Fresnel, luminance SRA).
    default = brdfd.fit(scan, cost="cf1", seed=2)
    assert default.document["fresnel"] == "exact"
    cli = json.loads(run("fit", "--input", str(SCAN), "--cost", "cf1", "--seed", "2", "--json"))
    same_bits(without_timing(default.document), without_timing(cli))
    # The paper's configuration, and one of its choices changed beside it.
    paper = brdfd.fit(scan, cost="cf1", seed=2, preset="paper")
    assert paper.document["fresnel"] == "incidence"
    cli = json.loads(run("fit", "--input", str(SCAN), "--cost", "cf1", "--seed", "2",
                         "--preset", "paper", "--json"))
    same_bits(without_timing(paper.document), without_timing(cli))
    mixed = brdfd.fit(scan, cost="cf1", seed=2, preset="paper", fresnel="exact")
    assert mixed.document["fresnel"] == "exact"
    with pytest.raises(ValueError, match="preset"):
        brdfd.fit(scan, cost="cf1", preset="gloss")


def test_a_model_option_equals_the_cli_bit_for_bit():
    scan = brdfd.read_scan(SCAN)
    got = brdfd.fit(scan, cost="cf1", seed=2, model="oren-nayar", fresnel="exact")
    cli = json.loads(run("fit", "--input", str(SCAN), "--cost", "cf1", "--seed", "2",
                         "--model", "oren-nayar", "--fresnel", "exact", "--json"))
    same_bits(without_timing(got.document), without_timing(cli))
    assert got.document["model"] == "oren-nayar"
    # The model at the fit's parameters is the fit's estimated BRDF, option and all.
    assert np.array_equal(brdfd.evaluate(got), got.estimated)
    two = brdfd.fit(scan, cost="cf1", seed=2, model="two-lobe")
    assert np.array_equal(brdfd.evaluate(two), two.estimated)
    assert np.array_equal(
        brdfd.evaluate(two.params, model="two-lobe", fresnel=two.document["fresnel"]),
        two.estimated)
    with pytest.raises(ValueError, match="needs the parameters sigma"):
        brdfd.evaluate(two.params, model="oren-nayar")
    with pytest.raises(ValueError, match="model"):
        brdfd.fit(scan, cost="cf1", model="lambert")


def test_hold_out_and_crossval_equal_the_cli_bit_for_bit():
    scan = brdfd.read_scan(SCAN)
    got = brdfd.fit(scan, cost="m2", seed=4, hold_out=["45as-15", "15as80"])
    cli = json.loads(run("fit", "--input", str(SCAN), "--cost", "m2", "--seed", "4",
                         "--hold-out", "45as-15,15as80", "--json"))
    same_bits(without_timing(got.document), without_timing(cli))
    assert [h["geometry"] for h in got.document["held_out"]] == ["15as80", "45as-15"]
    assert "45as-15" not in got.delta_e00 and len(got.delta_e00) == 12

    cv = brdfd.crossval(scan, "m2", fresnel="exact", seed=4)
    cli = json.loads(run("crossval", str(SCAN), "--cost", "m2", "--fresnel", "exact",
                         "--seed", "4", "--json"))
    same_bits(cv, cli)
    (one,) = cv["fits"]
    assert (one["cost"], one["model"], one["fresnel"]) == ("m2", "paper", "exact")
    assert len(one["held_out"]) == 12
    assert math.isclose(one["held_out_mean"],
                        sum(h["delta_e00"] for h in one["held_out"]) / 12, rel_tol=1e-12)
    with pytest.raises(ValueError, match="is not a geometry"):
        brdfd.fit(scan, cost="m2", hold_out=["45as-16"])


def test_bootstrap_intervals_hold_the_default_fit():
    # The default method ends in a local optimum, so the warm-started refits of the resamples
    # stay around it. (The paper GA's point need not be one: its refits may descend elsewhere.)
    r = brdfd.fit(brdfd.read_scan(SCAN), cost="m2", seed=3, bootstrap=4, sra="luminance")
    iv = r.intervals
    for name in ("ks", "alpha", "ior"):
        lo, hi = iv[name]
        assert lo <= r.params[name] <= hi or math.isclose(lo, hi), (name, lo, r.params[name], hi)


def test_real_xlsx_export_imports_and_fits_as_the_cli(tmp_path):
    scans = brdfd.import_export(XLSX)
    assert len(scans) >= 1
    scan = scans[0]
    assert scan.reference == "instrument calibration"
    lines = run("import-format", str(XLSX), "--out", str(tmp_path), "--json").splitlines()
    printed = [json.loads(line) for line in lines]
    assert [p["sample"] for p in printed] == [s.sample for s in scans]
    # The scan written by the CLI is the scan read here.
    file = Path(printed[0]["file"])
    assert json.loads(file.read_text()) == json.loads(scan.to_json())
    # And the colorimetry check is the one the CLI prints.
    checked = brdfd.import_export_checked(XLSX)
    for (_, check), p in zip(checked, printed):
        same_bits(check, p["colorimetry_check"])
    got = brdfd.fit(scan, cost="cf2")
    cli = json.loads(run("fit", "--input", str(file), "--cost", "cf2", "--json"))
    same_bits(without_timing(got.document), without_timing(cli))
    # No SRA readings: 12 geometries, no specular mean.
    assert len(got.delta_e00) == 12 and got.document["delta_e00_specular_mean"] is None


def test_result_values_are_plain_python_and_numpy():
    r = brdfd.fit(brdfd.read_scan(SCAN), cost="cf1", seed=1)
    assert isinstance(r.params["ks"], float) and isinstance(r.params["kd"], np.ndarray)
    assert r.params["kd"].shape == (31,)
    assert list(r.delta_e00) == brdfd.geometries()
    assert all(isinstance(v, float) for v in r.delta_e00.values())
    assert r.delta_e00_mean == pytest.approx(np.mean(list(r.delta_e00.values())))
    assert r.cost == r.document["cost"] and r.cost > 0
    lab = r.lab["45as15"]
    assert lab["measured"].shape == (3,) and lab["fitted"].shape == (3,)
    assert r.intervals is None


def test_evaluate_is_the_fits_model():
    r = brdfd.fit(brdfd.read_scan(SCAN), cost="cf2", seed=2)
    # The fit's estimated BRDF is the model at its parameters: the same numbers.
    a = brdfd.evaluate(r)
    assert a.shape == (14, 31)
    assert np.array_equal(a, r.estimated)
    b = brdfd.evaluate(r.params, ["45as15", "sra-60"], [400, 550, 700],
                       fresnel=r.document["fresnel"])
    i15, i60 = brdfd.geometries().index("45as15"), brdfd.geometries().index("sra-60")
    assert np.array_equal(b, r.estimated[[i15, i60]][:, [0, 15, 30]])
    # A geometry as angles: the 45as15 geometry's own angles give its values.
    g = next(g for g in brdfd.GEOMETRIES if g["name"] == "45as15")
    c = brdfd.evaluate(r.params, [(g["theta_i"], g["theta_r"], g["phi_r"])], [550],
                       fresnel=r.document["fresnel"])
    assert np.array_equal(c, b[:1, 1:2])
    # Diffuse only (ks = 0): kd at every geometry.
    flat = dict(r.params, ks=0.0)
    assert np.array_equal(brdfd.evaluate(flat)[3], r.params["kd"])
    with pytest.raises(ValueError, match="555 nm is not one of the model's bands"):
        brdfd.evaluate(r.params, None, [555])
    with pytest.raises(ValueError, match="unknown geometry"):
        brdfd.evaluate(r.params, ["45as99"])


def test_errors_name_the_problem(tmp_path):
    with pytest.raises(OSError, match="nope.scan.json"):
        brdfd.read_scan(tmp_path / "nope.scan.json")
    with pytest.raises(ValueError, match="cost function \"cf9\""):
        brdfd.fit(brdfd.read_scan(SCAN), cost="cf9")


@pytest.fixture(scope="module")
def demo_store(tmp_path_factory):
    d = tmp_path_factory.mktemp("demo")
    run("demo", "--dir", str(d / "demo"), "--jobs", "2")
    db = d / "demo" / "brdfd.db"
    assert db.exists()
    tidy = d / "tidy"
    run("export-format", "--format", "tidy", "--all", "--db", str(db), "--out", str(tidy))
    return db, tidy


def test_store_tables_are_the_tidy_export(demo_store):
    pd = pytest.importorskip("pandas")
    db, tidy = demo_store
    store = brdfd.Store(db)
    for got, name in ((store.scans(), "spectra.csv"), (store.fits(), "fits.csv")):
        assert isinstance(got, pd.DataFrame)
        want = pd.read_csv(tidy / name, float_precision="round_trip",
                           dtype={"reason": "string", "station": "string"})
        assert len(got) > 0
        pd.testing.assert_frame_equal(got, want, check_exact=True)
    fits = store.fits()
    assert set(fits["cost_function"]) == {"cf1", "cf2", "m2"}


def test_store_without_pandas_gives_lists_of_dicts(demo_store, monkeypatch):
    db, tidy = demo_store
    monkeypatch.setitem(sys.modules, "pandas", None)
    rows = brdfd.Store(db).fits()
    assert isinstance(rows, list) and isinstance(rows[0], dict)
    import csv
    with open(tidy / "fits.csv", newline="") as f:
        want = list(csv.DictReader(f))
    assert len(rows) == len(want)
    assert list(rows[0]) == list(want[0])
    for r, w in zip(rows, want):
        for k, v in w.items():
            if v == "":
                assert r[k] is None
            elif isinstance(r[k], float):
                assert r[k] == float(v)
            else:
                assert str(r[k]) == v


def test_store_that_is_missing_is_named(tmp_path):
    with pytest.raises(ValueError, match="no store at"):
        brdfd.Store(tmp_path / "missing.db").fits()


def test_spectra_as_colour_spectral_distribution():
    colour = pytest.importorskip("colour")
    r = brdfd.fit(brdfd.read_scan(SCAN), cost="cf2", seed=5)
    sd = r.spectral_distribution("45as15", "fitted")
    assert isinstance(sd, colour.SpectralDistribution)
    assert list(sd.wavelengths) == list(range(400, 701, 10))
    i = brdfd.geometries().index("45as15")
    assert np.array_equal(sd.values, np.pi * r.estimated[i])
    m = r.spectral_distribution("45as15")
    assert np.array_equal(m.values, r.reflectance("45as15", "measured"))
