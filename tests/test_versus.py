"""``pyclpt bench --versus mitsuba`` without Mitsuba: a fake "Mitsuba python" that speaks the
driver's protocol stands in for it (the table, the ratio and the means come out); a missing or
broken one is a clear error naming the option and the variable; the driver compiles and edits a
scene's XML as documented. Timings are never checked."""
from __future__ import annotations

import argparse
import json
import py_compile
import stat
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pyclpt.cli import main

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))
try:
    from pyclpt.bench import mitsuba_driver, versus
except ModuleNotFoundError:
    from bench import mitsuba_driver, versus

FAKE = """#!{python}
import json, sys
print(json.dumps({{"event": "ready", "mitsuba_version": "3.9.1", "variant": "llvm_ad_rgb", "load_s": 0.0,
                  "warmup_s": [0.1]}}), flush=True)
for line in sys.stdin:
    w = line.split()
    if w[0] == "quit":
        break
    print(json.dumps({{"event": "render", "seed": int(w[1]), "seconds": 0.002, "mean": [0.25, 0.15, 0.06]}}),
          flush=True)
"""
QUICK = ["--quick", "--scenes", "builtin/cornell-box", "--cornell-resolution", "8x8", "--cornell-spp", "1"]


def _script(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "fake-python"
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def test_versus_with_a_fake_mitsuba_writes_the_table(tmp_path, monkeypatch, capsys):
    fake = _script(tmp_path, FAKE.format(python=sys.executable))
    monkeypatch.setenv("PYCLPT_MITSUBA_PYTHON", str(fake))
    out = tmp_path / "out"
    assert main(["bench", "--versus", "mitsuba", *QUICK, "-o", str(out)]) == 0
    md = (out / "versus.md").read_text()
    res = json.loads((out / "versus.json").read_text())
    assert "pyclpt / Mitsuba" in md and "Mitsuba 3.9.1, variant llvm_ad_rgb" in md
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
        from pyclpt.bench import report
    except ModuleNotFoundError:
        from bench import report
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
