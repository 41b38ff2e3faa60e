"""``pyclpt bench --versus mitsuba`` without Mitsuba: a fake "Mitsuba python" that speaks the
driver's protocol stands in for it (the table, the ratio and the means come out; its images have a
known relMSE against its reference, so the time-to-equal-relMSE figures can be checked); a missing or
broken one is a clear error naming the option and the variable; the driver compiles and edits a
scene's XML as documented. Timings are never checked."""
from __future__ import annotations

import argparse
import json
import math
import py_compile
import stat
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from pyclpt.cli import main

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))
try:
    from pyclpt.bench.report import mitsuba_driver, versus
except ModuleNotFoundError:
    from bench.report import mitsuba_driver, versus

# A stand-in for bench/report/mitsuba_driver.py: its reference is the constant REF, its renders REF plus a
# checkerboard of +-NOISE (so their relMSE against the reference is NOISE^2 / (REF^2 + eps) exactly);
# every command is appended to the file LOG.
FAKE = """#!{python}
import json, sys
import numpy as np
REF, NOISE, LOG = {ref}, {noise}, {log!r}
a = sys.argv
w, h = (int(a[a.index(k) + 1]) if k in a else 1 for k in ("--width", "--height"))
ref = np.full((h, w, 3), REF, np.float32)
sign = np.where((np.arange(h)[:, None] + np.arange(w)[None, :]) % 2 == 0, 1.0, -1.0)[..., None]
print(json.dumps({{"event": "ready", "mitsuba_version": "3.9.1", "variant": "llvm_ad_rgb", "load_s": 0.0,
                  "warmup_s": [0.1]}}), flush=True)
for line in sys.stdin:
    words = line.split()
    open(LOG, "a").write(line)
    if words[0] == "quit":
        break
    if words[0] == "reference":
        np.save(words[3], ref)
        print(json.dumps({{"event": "reference", "passes": int(words[1]), "spp": 0, "seconds": 0.5,
                          "mean": [REF] * 3}}), flush=True)
        continue
    if len(words) > 2:
        np.save(words[2], (ref + NOISE * sign).astype(np.float32))
    print(json.dumps({{"event": "render", "seed": int(words[1]), "seconds": 0.002, "mean": [0.25, 0.15, 0.06]}}),
          flush=True)
"""
QUICK = ["--quick", "--scenes", "builtin/cornell-box", "--cornell-resolution", "8x8", "--cornell-spp", "1"]


def _script(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "fake-python"
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def _fake(tmp_path: Path, ref: float = 0.25, noise: float = 0.05) -> Path:
    return _script(tmp_path, FAKE.format(python=sys.executable, ref=ref, noise=noise, log=str(tmp_path / "fake.log")))


def test_versus_with_a_fake_mitsuba_writes_the_table(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PYCLPT_MITSUBA_PYTHON", str(_fake(tmp_path)))
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "out"
    assert main(["bench", "--versus", "mitsuba", *QUICK, "-o", str(out)]) == 0
    md = (out / "versus.md").read_text()
    res = json.loads((out / "versus.json").read_text())
    assert "pyclpt / Mitsuba" in md and "Mitsuba 3.9.1, variant llvm_ad_rgb" in md
    assert "- date: 20" in md and "time to equal relMSE, Mitsuba / pyclpt" in md
    (case,) = res["cases"]
    assert set(case["methods"]) == {"megakernel", "wavefront-soa", "mitsuba"}
    assert case["methods"]["mitsuba"]["msamples_per_s"] == pytest.approx(8 * 8 / 0.002 / 1e6)
    for name in ("megakernel", "wavefront-soa"):
        m = case["methods"][name]
        ratio = m["msamples_per_s"] / case["methods"]["mitsuba"]["msamples_per_s"]
        row = next(line for line in md.splitlines() if f"| {name}" in line)
        assert f"{ratio:.2f}x" in row
        assert "0.2500 0.1500 0.0600" in row  # Mitsuba's means beside pyclpt's
        assert all(x > 0 for x in m["mean"])


@pytest.mark.parametrize("how", ["missing", "not-executable", "broken", "unset"])
def test_a_missing_or_broken_mitsuba_python_is_a_clear_error(how, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("PYCLPT_MITSUBA_PYTHON", raising=False)
    args = ["bench", "--versus", "mitsuba", *QUICK, "-o", str(tmp_path / "out")]
    if how == "missing":
        args += ["--mitsuba-python", str(tmp_path / "nope" / "python")]
    elif how == "not-executable":
        (tmp_path / "python").write_text("")
        args += ["--mitsuba-python", str(tmp_path / "python")]
    elif how == "broken":  # runs, but is not a Mitsuba python: fails like `import mitsuba` would
        monkeypatch.setenv("PYCLPT_MITSUBA_PYTHON", str(_script(
            tmp_path, f"#!{sys.executable}\nimport sys\nsys.exit('ModuleNotFoundError: No module named mitsuba')\n")))
    assert main(args) != 0
    err = capsys.readouterr().err
    assert "--mitsuba-python" in err and "PYCLPT_MITSUBA_PYTHON" in err, err
    if how == "broken":
        assert "No module named mitsuba" in err


def test_plain_bench_is_unchanged_by_versus_options():
    try:
        from pyclpt.bench.report import report
    except ModuleNotFoundError:
        from bench.report import report
    a = report.build_parser().parse_args([])
    assert a.versus is None


def test_driver_compiles_and_edits_the_scene(tmp_path):
    py_compile.compile(str(versus.DRIVER), doraise=True)
    xml = """<scene version="0.5.0"><integrator type="sppm"><integer name="maxDepth" value="65"/></integrator>
    <sensor type="perspective"><film type="ldrfilm"><integer name="width" value="1024"/>
    <rfilter type="tent"/></film><sampler type="ldsampler"><integer name="sampleCount" value="8"/></sampler>
    </sensor><bsdf type="roughconductor"><float name="extEta" value="1"/><string name="material" value="Al"/></bsdf>
    <texture type="bitmap"><string name="filterType" value="trilinear"/></texture>
    <emitter type="sunsky"><float name="sunRadiusScale" value="2"/></emitter></scene>"""
    a = argparse.Namespace(max_depth=8, rr_depth=3, spp=16, width=64, height=48)
    root = ET.fromstring(mitsuba_driver.edit_xml(xml, a))
    (integ,) = root.findall("integrator")
    assert integ.get("type") == "path"
    assert {e.get("name"): e.get("value") for e in integ} == {"max_depth": "8", "rr_depth": "3"}
    (film,) = root.findall("sensor/film")
    assert film.get("type") == "hdrfilm" and film.find("rfilter").get("type") == "box"
    assert {e.get("name"): e.get("value") for e in film.findall("integer")} == {"width": "64", "height": "48"}
    (sampler,) = root.findall("sensor/sampler")
    assert sampler.get("type") == "independent" and sampler.find("integer").get("value") == "16"
    assert [e.get("name") for e in root.find("bsdf")] == ["material"]  # Mitsuba 3 refuses extEta
    assert root.find("texture/string").get("value") == "bilinear"
    aperture = root.find("emitter/float")
    assert aperture.get("name") == "sun_aperture" and float(aperture.get("value")) == pytest.approx(2 * 0.5358)
    rotation = root.find("emitter/transform")  # 0.5's +y-up sky frame into Mitsuba 3's +z-up one
    assert rotation.get("name") == "toWorld" and rotation.find("rotate").attrib == {"x": "1", "angle": "-90"}
    assert root.find("emitter/float[@name='albedo']").get("value") == "0.2"  # Mitsuba 0.5's default


def test_relmse_is_zero_against_itself_and_the_noise_variance_against_a_noisy_copy():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.0, 2.0, (64, 48, 3))
    assert versus.relmse(ref, ref) == 0.0
    sign = np.where(rng.random(ref.shape) < 0.5, -1.0, 1.0)
    noisy = ref + 0.1 * sign  # every pixel off by exactly 0.1
    assert versus.relmse(noisy, ref) == pytest.approx(np.mean(0.01 / (ref**2 + versus.RELMSE_EPS)))
    assert versus.RELMSE_EPS == 1e-2  # as bench/evaluations/denoise_metrics.py's
    # Gaussian noise of variance v on a constant c: relMSE -> v / (c^2 + eps); at n spp the variance is v1 / n
    flat = np.full((256, 256, 3), 0.5)
    for spp in (1, 4):
        x = flat + rng.normal(0.0, 0.2 / math.sqrt(spp), flat.shape)
        assert versus.relmse(x, flat) == pytest.approx(0.04 / spp / (0.25 + 1e-2), rel=0.02)
    assert versus.relmse(np.zeros((4, 4, 4)), np.zeros((4, 4, 3))) == 0.0  # an alpha channel is ignored


def test_time_to_equal_relmse_points_the_right_way():
    # pyclpt twice as fast at the same relMSE: it reaches any relMSE in half the time -> 2x
    assert versus.time_ratio(0.1, 1.0, 0.1, 2.0) == pytest.approx(2.0)
    # the same time, pyclpt four times the relMSE: it needs four times the samples -> 0.25x
    assert versus.time_ratio(0.4, 1.0, 0.1, 1.0) == pytest.approx(0.25)
    # a render identical to its reference (a black image), a missing figure: no ratio
    assert versus.time_ratio(0.1, 1.0, 0.0, 1.0) is None
    assert versus.time_ratio(None, 1.0, 0.1, 1.0) is None
    assert versus.time_ratio(float("nan"), 1.0, 0.1, 1.0) is None
    assert versus.geometric_mean([1.0, 4.0]) == pytest.approx(2.0)


def test_noise_figures_of_renders_against_their_references():
    own = np.full((8, 8, 3), 0.5)
    other = np.full((8, 8, 3), 0.6)
    runs = [{"image": own}, {"image": own + 0.1}]
    f = versus.noise_figures(runs, own, other, median_s=2.0)
    expected = 0.01 / (0.25 + 1e-2)
    assert f["relmse"] == pytest.approx([0.0, expected])
    assert f["relmse_mean"] == pytest.approx(expected / 2)
    assert f["relmse_x_s"] == pytest.approx(expected)
    assert f["relmse_cross"] == pytest.approx([0.01 / (0.36 + 1e-2), 0.0])  # the bias shows against the other
    assert versus.noise_figures([{"image": None}], own, other, 1.0)["relmse_x_s"] is None


def test_fake_mitsuba_relmse_ratio_and_cached_references(tmp_path, monkeypatch):
    monkeypatch.setenv("PYCLPT_MITSUBA_PYTHON", str(_fake(tmp_path, ref=0.25, noise=0.05)))
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path / "cache"))
    args = ["bench", "--versus", "mitsuba", *QUICK, "--repeats", "2"]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    res = json.loads((tmp_path / "a" / "versus.json").read_text())
    (case,) = res["cases"]
    ms = case["methods"]["mitsuba"]
    expected = 0.05**2 / (0.25**2 + 1e-2)  # the fake's renders against its own reference
    assert ms["relmse"] == pytest.approx([expected] * 2, rel=1e-5)
    assert ms["relmse_x_s"] == pytest.approx(expected * ms["median_s"], rel=1e-5)
    refs = case["references"]
    assert refs["mitsuba"]["spp"] == refs["pyclpt"]["spp"] == 1 * 4  # --cornell-spp 1, --quick's factor 4
    assert refs["pyclpt"]["method"] == "megakernel" and not refs["pyclpt"]["cached"]
    for name in ("megakernel", "wavefront-soa"):
        m = case["methods"][name]
        assert len(m["relmse"]) == 2 and m["relmse_mean"] > 0 and m["relmse_cross_mean"] > 0
        ratio = ms["relmse_mean"] * ms["median_s"] / (m["relmse_mean"] * m["median_s"])
        assert m["time_to_equal_relmse"] == pytest.approx(ratio)
        row = next(line for line in (tmp_path / "a" / "versus.md").read_text().splitlines() if f"| {name}" in line)
        assert f"| {ratio:.2f}x |" in row and f"{expected:.3g}" in row
    assert res["summary"]["megakernel"]["all"] == pytest.approx(case["methods"]["megakernel"]["time_to_equal_relmse"])
    assert sum(line.startswith("reference ") for line in (tmp_path / "fake.log").open()) == 1
    # the second run reads both references from the cache: the fake is asked for none
    assert main([*args, "-o", str(tmp_path / "b")]) == 0
    again = json.loads((tmp_path / "b" / "versus.json").read_text())["cases"][0]
    assert again["references"]["pyclpt"]["cached"] and again["references"]["mitsuba"]["cached"]
    assert sum(line.startswith("reference ") for line in (tmp_path / "fake.log").open()) == 1
    assert again["references"]["relmse_pyclpt_vs_mitsuba"] == pytest.approx(refs["relmse_pyclpt_vs_mitsuba"])


def test_a_render_equal_to_its_reference_has_no_ratio(tmp_path, monkeypatch):
    monkeypatch.setenv("PYCLPT_MITSUBA_PYTHON", str(_fake(tmp_path, ref=0.0, noise=0.0)))  # a black scene
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path / "cache"))
    assert main(["bench", "--versus", "mitsuba", *QUICK, "-o", str(tmp_path / "out")]) == 0
    (case,) = json.loads((tmp_path / "out" / "versus.json").read_text())["cases"]
    assert case["methods"]["mitsuba"]["relmse"] == [0.0]
    assert case["methods"]["megakernel"]["time_to_equal_relmse"] is None
    row = next(line for line in (tmp_path / "out" / "versus.md").read_text().splitlines() if "| megakernel" in line)
    assert "| 0 / 0 |" not in row and row.split(" | ")[12] == "-"
