"""The timing report generator (``pyclpt bench``): a --quick run as a smoke test (every file and
section present, figures sane and consistent with each other), regeneration from the saved JSON,
and small runs of the odd paths. Timings are never checked against thresholds."""
from __future__ import annotations

import csv
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import pyclpt
from pyclpt.cli import main

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # a source checkout: bench/report/ beside pyclpt/ (installed: pyclpt.bench.report)
    sys.path.insert(0, str(REPO))
try:
    from pyclpt.bench.report import analysis as A
    from pyclpt.bench.report import document, embree_ceiling, report, runner
except ModuleNotFoundError:
    from bench.report import analysis as A
    from bench.report import document, embree_ceiling, report, runner

SECTIONS = ["Summary", "Machine and software", "Settings", "Scenes", "Table 1 analog: frames per second",
            "Fig. 6 analog: render time for many samples", "Fig. 7 analog: time against depth",
            "Throughput: samples/s and rays/s", "Per-kernel time", "Occupancy: paths alive per bounce",
            "Cost against triangle count", "Embree ceiling", "How this was measured", "Raw results"]
ALWAYS_PNG = ["table1_fps.png", "fig6_spp_time.png", "fig7_time_vs_depth.png", "kernels.png", "occupancy.png",
              "rays_per_second.png"]
WAVEFRONT_KERNELS = {"path_init", "intersect", "miss", "process_hit", "shadow_test", "light_contribution",
                     "sample_bsdf"}


def _bench(*args: str) -> None:
    assert main(["bench", *args, "--no-progress"]) == 0


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("bench-quick")
    _bench("--quick", "-o", str(out))
    return out, json.loads((out / "results.json").read_text())


def _finite_positive(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x) and x > 0


@pytest.mark.slow
def test_quick_report_has_every_file_and_section(quick):
    out, res = quick
    for name in ["report.md", "report.html", "results.json", "results.csv", *ALWAYS_PNG]:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    for png in out.glob("*.png"):
        assert png.read_bytes()[:4] == b"\x89PNG"
    md = (out / "report.md").read_text()
    for s in SECTIONS:
        assert f"\n## {s}\n" in md, s
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert set(ALWAYS_PNG) <= set(images)
    assert all((out / i).is_file() for i in images)
    html = (out / "report.html").read_text()
    assert html.count("src=\"data:image/png;base64,") == len(images)
    assert "missing image" not in html
    for s in SECTIONS:
        assert s.split(":")[0] in html
    # header: machine, OpenCL, PoCL/LLVM, pyclpt revision, every setting
    meta = res["meta"]
    for key in ("cpu", "cores", "os", "pyclpt", "pyopencl", "opencl", "date", "elapsed_s"):
        assert meta.get(key) is not None, key
    assert meta["opencl"]["device"] in md and meta["opencl"]["driver_version"] in md
    if pyclpt.default_device().is_pocl:
        assert meta["opencl"]["pocl_version"] and meta["opencl"]["llvm_version"]
    for key in ("scenes", "methods", "depths", "spp", "resolution", "repeats", "device"):
        assert f"| {key} |" in md, key
    assert res["settings"]["quick"] is True


@pytest.mark.slow
def test_quick_report_figures_are_sane(quick):
    _, res = quick
    st = res["settings"]
    measured = A.scenes(res)
    assert [s["scene"] for s in measured][:1] == ["cornell-box"]  # built-in, needs no shared folder
    assert st["methods"] == ["megakernel", "wavefront-aos", "wavefront-soa"]
    for s in A.skipped(res):
        assert s["skipped"].strip(), s
    for s in measured:
        assert s["triangles"] > 0 and s["load_s"] >= 0 and s["setup_s"] >= 0
        for m in st["methods"]:
            for d in st["depths"]:
                assert A.find(res, s["scene"], m, d) is not None, (s["scene"], m, d)
    assert len(res["runs"]) == len(measured) * len(st["methods"]) * len(st["depths"])
    for r in res["runs"]:
        ms = r["ms"]
        assert all(_finite_positive(ms[k]) for k in ("median", "min", "max"))
        assert ms["min"] <= ms["median"] <= ms["max"]
        assert len(r["frames_ms"]) == st["repeats"] == r["repeats"]
        assert _finite_positive(r["device_ms"]["median"])
        assert r["cpu_ms"]["median"] >= 0 and len(r["frames_cpu_ms"]) == r["repeats"]
        assert r["seeds"] == list(range(1, r["repeats"] + 1))  # every method renders the same frames
        assert r["compile_s"] >= 0 and r["setup_s"] >= 0
        names = {k["kernel"] for k in r["kernels"]}
        assert ("megakernel" in names) if r["method"] == "megakernel" else (WAVEFRONT_KERNELS <= names)
        assert all(k["ms"] >= 0 for k in r["kernels"])
        assert math.isclose(sum(k["ms"] for k in r["kernels"]),
                            sum(r["frames_device_ms"]) / len(r["frames_device_ms"]), rel_tol=1e-6)
        # rays: every pixel shoots a camera ray, and so does each of a splatting film's margin (its tent or
        # gaussian reaches into the image from there); depth 1 traces nothing else (no bounce, no light sample)
        c = r["counts"]
        assert r["pixels"] == r["width"] * r["height"] and r["traced"] >= r["pixels"]
        assert c["camera"] == r["traced"]
        assert c["total"] == c["camera"] + c["extension"] + c["shadow"] >= r["pixels"]
        if r["depth"] == 1:
            assert c["extension"] == 0 and c["shadow"] == 0
        # the two wavefront layouts count their rays independently and must agree (same estimator, same
        # seeds) unless finish_paths took their last paths (it counts none of its bounces); the megakernel
        # cannot count: its counts are the SoA run's or those of a counting run, and its row says so
        soa = A.find(res, r["scene"], "wavefront-soa", r["depth"])
        tail = any(b.get("tail") for b in r.get("bounces") or []) if r["method"] != "megakernel" else False
        if r["method"] == "megakernel":
            assert r["counts_source"] in ("wavefront-soa run of the same seeds", report.COUNTING_RUN)
            assert c == soa["counts"]
        else:
            assert r["counts_source"] == (report.COUNTING_RUN if tail else "measured")
        if r["method"] == "wavefront-aos":
            assert c == soa["counts"]
            assert r["bounces"] == soa["bounces"]
        # derived figures agree with the times
        d = A.derived(res, r)
        assert math.isclose(d["fps"], 1e3 / ms["median"])
        assert math.isclose(d["samples_per_s"], r["pixels"] * d["fps"])
        assert math.isclose(d["mrays_per_s"], c["total"] * d["fps"] / 1e6)
        mk = A.find(res, r["scene"], "megakernel", r["depth"])
        assert math.isclose(d["speedup"], mk["ms"]["median"] / ms["median"])
        if r["method"] == "megakernel":
            assert d["speedup"] == 1.0
        # occupancy: paths alive never grow, and the queues add up
        b = r["bounces"]
        assert b[0]["rays"] == r["traced"] and b[0]["bounce"] == 0
        for x, y in zip(b, b[1:]):
            assert x["rays"] == x["hits"] + x["misses"]
            assert y["rays"] <= x["hits"]
            assert x["unoccluded"] <= x["shadow_rays"] <= x["hits"]
        assert len(b) - 1 <= r["depth"]
        if r["depth"] == st["spp_depth"]:
            spp = r["spp_run"]
            assert spp["spp"] == st["spp"] and _finite_positive(spp["seconds"])
            assert spp["chunks"] == min(4, st["spp"])
            sp = A.spp_speedup(res, r)
            assert math.isclose(sp, mk["spp_run"]["seconds"] / spp["seconds"])
        else:
            assert "spp_run" not in r
    assert A.counts_agree(res) is True
    # and a fresh wavefront renderer, not a copy, counts the same rays for the same seeds
    first = A.find(res, "cornell-box", "wavefront-soa", max(st["depths"]))
    recount = runner.count_rays(pyclpt.load("cornell-box"), first["depth"], first["width"], first["height"],
                                first["seeds"])
    assert recount == first["counts"]
    for s in measured:
        e = res["embree"][s["scene"]]
        assert e["triangles"] == s["triangles"]
        for kind in ("primary", "secondary", "shadow"):
            assert _finite_positive(e[kind]["mrays_per_s"]) and e[kind]["rays"] > 0
        assert 0 < e["primary"]["hit_fraction"] <= 1


@pytest.mark.slow
def test_quick_report_tables_and_csv_match_results(quick):
    out, res = quick
    md = (out / "report.md").read_text()
    table1 = md.split("## Table 1 analog")[1].split("\n## ")[0]
    for s in A.scenes(res):
        row = next(line for line in table1.splitlines() if line.startswith(f"| {s['scene']} |"))
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert cells[1] == f"{s['triangles']:,}"
        fps = [float(c.replace(",", "")) for c in cells[3:6]]
        speedups = [float(c.rstrip("x")) for c in cells[6:8]]
        assert all(f > 0 for f in fps)
        for f, sp in zip(fps[1:], speedups):  # speed-up = method FPS / megakernel FPS (rounded)
            assert sp == pytest.approx(f / fps[0], rel=0.02, abs=0.01)
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(res["runs"])
    for row, r in zip(rows, res["runs"]):
        assert row["scene"] == r["scene"] and row["method"] == r["method"] and int(row["depth"]) == r["depth"]
        assert float(row["ms_median"]) == pytest.approx(r["ms"]["median"])
        assert float(row["fps"]) == pytest.approx(1e3 / r["ms"]["median"])
        assert int(float(row["total_rays"])) >= r["pixels"]
    assert "Command to repeat this run: `pyclpt bench --scenes" in md


@pytest.mark.slow
def test_report_regenerates_from_saved_json(quick, tmp_path):
    out, res = quick
    _bench("--from-json", str(out / "results.json"), "-o", str(tmp_path))
    assert (tmp_path / "report.md").read_text() == (out / "report.md").read_text()
    assert json.loads((tmp_path / "results.json").read_text()) == res
    assert (tmp_path / "results.csv").read_text() == (out / "results.csv").read_text()
    for name in ["report.html", *ALWAYS_PNG]:
        assert (tmp_path / name).is_file(), name
    # in place: the report is rewritten identically and results.json is left alone
    before = (out / "results.json").read_bytes()
    md = (out / "report.md").read_text()
    _bench("--from-json", str(out / "results.json"))
    assert (out / "report.md").read_text() == md
    assert (out / "results.json").read_bytes() == before


def test_megakernel_only_counts_rays_with_a_wavefront_pass(tmp_path, monkeypatch):
    """Without a wavefront run to take them from, the megakernel's rays are counted by a
    wavefront run of the same seeds; a missing shared folder skips its scenes with a note."""
    monkeypatch.setenv("PYCLPT_SCENES", str(tmp_path / "no-such-folder"))
    _bench("--scenes", "cornell-box", "cornell-bunny", "shared", "shared/living-room", "--integrators", "megakernel",
           "--depths", "2", "--table-depth", "2", "--spp", "1", "--spp-depth", "2", "--resolution", "8x6",
           "--repeats", "2", "--warmup", "0", "--no-embree", "-o", str(tmp_path / "r"))
    res = json.loads((tmp_path / "r" / "results.json").read_text())
    assert [s["scene"] for s in A.scenes(res)] == ["cornell-box"]
    notes = {s["scene"]: s["skipped"] for s in A.skipped(res)}
    assert set(notes) == {"cornell-bunny", "shared", "shared/living-room"}
    assert "shared scene folder" in notes["cornell-bunny"] or "PYCLPT_SCENES" in notes["cornell-bunny"]
    (run,) = res["runs"]
    assert run["method"] == "megakernel" and run["counts_source"].startswith("wavefront-soa counting run")
    assert run["counts"]["camera"] == 48 and run["counts"]["total"] >= 48
    assert res["embree"] == {}
    md = (tmp_path / "r" / "report.md").read_text()
    assert "Skipped scenes:" in md and "`cornell-bunny`" in md
    assert "Not measured (`--no-embree`)." in md
    assert "| scene | triangles | resolution | megakernel FPS |\n" in md  # no speed-up columns


def test_a_scene_that_fails_to_load_is_a_note_not_an_error(tmp_path):
    bad = tmp_path / "broken.json"
    bad.write_text("{ not json")
    _bench("--scenes", str(bad), "cornell-box", "--integrators", "wavefront", "--layouts", "soa", "--depths", "1",
           "--spp", "1", "--spp-depth", "1", "--table-depth", "1", "--resolution", "4x4", "--repeats", "1",
           "--no-embree", "-o", str(tmp_path / "r"))
    res = json.loads((tmp_path / "r" / "results.json").read_text())
    (skip,) = A.skipped(res)
    assert skip["scene"] == "broken" and "could not be loaded" in skip["skipped"]
    assert [r["method"] for r in res["runs"]] == ["wavefront-soa"]
    assert A.derived(res, res["runs"][0])["speedup"] is None  # no megakernel to compare with


def test_nothing_measured_exits_non_zero(tmp_path, capsys):
    """Every scene skipped: no empty report and exit status 0, but an error naming why."""
    bad = tmp_path / "broken.json"
    bad.write_text("{ not json")
    out = tmp_path / "r"
    rc = main(["bench", "--scenes", str(bad), "no-such-scene", "--no-embree", "--no-progress", "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 1, err
    assert "nothing was measured" in err and "broken" in err and "no-such-scene" in err
    assert not (out / "report.md").exists()
    res = json.loads((out / "results.json").read_text())  # the reasons are kept
    assert res["runs"] == [] and len(A.skipped(res)) == 2
    assert main(["bench", "--from-json", str(out / "results.json")]) == 1  # nor regenerated from it
    assert "no measurement" in capsys.readouterr().err
    assert not (out / "report.md").exists()


def test_bench_arguments_are_checked(capsys):
    for bad in (["--resolution", "12"], ["--depths", "0"], ["--integrators", "gpu"], ["--repeats", "x"]):
        with pytest.raises(SystemExit) as e:
            main(["bench", *bad])
        assert e.value.code == 2, bad
    assert "--from-json" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["bench", "--help"])
    assert e.value.code == 0
    assert "--quick" in capsys.readouterr().out
    assert main(["bench", "--from-json", "/no/such/results.json"]) == 1
    assert "error" in capsys.readouterr().err


def test_settings_quick_and_explicit_options():
    s = report.settings_from(report.build_parser().parse_args(["--quick", "--repeats", "5", "--depths", "2"]))
    assert s["quick"] and s["repeats"] == 5 and s["resolution"] == report.QUICK["resolution"]
    assert s["depths"] == sorted({2, s["table_depth"], s["spp_depth"]})
    s = report.settings_from(report.build_parser().parse_args([]))
    assert s["depths"] == [1, 2, 3, 4, 8, 16, 32, 64] and s["methods"][0] == "megakernel"
    assert s["resolution"] == "512x512" and not s["quick"]
    with pytest.raises(ValueError):
        report.settings_from(report.build_parser().parse_args(["--warmup", "-1"]))


def test_document_markdown_and_html():
    doc = document.Document("T")
    doc.add(document.Heading(1, "A"), document.Para("x `a<b` **bold**"),
            document.Table(["h", "v"], [["a|b", "1"]]), document.Bullets(["i"]), document.Image("nope.png", "alt"))
    md = document.to_markdown(doc)
    assert md.startswith("# T\n") and "## A" in md and "| a\\|b | 1 |" in md and "![alt](nope.png)" in md
    html = document.to_html(doc, Path("/nonexistent"))
    assert "<code>a&lt;b</code>" in html and "<b>bold</b>" in html and "missing image nope.png" in html


def test_embree_ceiling_on_the_cornell_box(cornell_box):
    e = embree_ceiling.measure(cornell_box, 16, 12, threads=2, repeats=1, min_rays=1000)
    assert e["primary"]["rays"] == 1000  # several rays per pixel: at least min_rays
    assert 0.5 < e["primary"]["hit_fraction"] <= 1
    for kind in ("primary", "secondary", "shadow"):
        assert e[kind]["mrays_per_s"] > 0 and np.isfinite(e[kind]["best_s"])
    assert A.ceiling_mrays(e) > 0


def test_embree_gap_traces_what_embree_traces():
    """bench/studies/embree_gap.py (docs/bvh.md, "Against Embree"): the kernels and Embree trace the same camera,
    bounce and shadow rays of the built-in box and give the same answers, with a rate for each."""
    gap = pytest.importorskip("bench.studies.embree_gap", reason="a source checkout's bench/studies")
    from bench.studies.bvh_traversal import Tracer

    r = gap.measure(Tracer(), "cornell-box", 48, 1, 1, threads=2)
    assert r["mismatches"] == {"camera": 0, "bounce": 0, "shadow": 0}
    assert r["rays"]["camera"] == 48 * 48 and r["rays"]["bounce"] == r["rays"]["shadow"] > 1000
    assert all(v > 0 and math.isfinite(v) for v in r["mrays_per_s"].values())


def test_trees_ab_times_two_trees_in_alternation(capsys):
    """bench/studies/trees_ab.py (docs/benchmarks.md, "The living room's environment"): two processes, each
    importing the tree it is given, render in alternation; a tree that is not a checkout is refused by name."""
    ab = pytest.importorskip("bench.studies.trees_ab", reason="a source checkout's bench/studies")
    root = str(Path(__file__).resolve().parents[1])  # the checkout (pyclpt may be installed elsewhere)
    assert ab.main([root, root, "--scene", "builtin/cornell-box", "--size", "16", "--spp", "1", "--rounds", "2"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("builtin/cornell-box, megakernel, 16x16, 1 spp, depth 8, 2 rounds on ")
    assert re.search(r"old \d+\.\d+ s, new \d+\.\d+ s, speedup \d+\.\d+x$", line), line
    with pytest.raises(SystemExit):
        ab.main([root, str(Path(root) / "docs"), "--rounds", "1"])
    assert "docs: not a pyclpt checkout" in capsys.readouterr().err
    # the sides run in the trees' folders: a shared scene or a file goes to them as an absolute path
    assert ab.scene_file("builtin/cornell-box") == "cornell-box"
    box = str(Path(root) / "scenes" / "cornell-box.json")
    assert ab.scene_file(box) == box
    with pytest.raises(SystemExit, match="no-such-scene"):
        ab.scene_file("no-such-scene")


def test_isa_section_of_the_report(tmp_path):
    """`pyclpt bench --isa`: the GPU ISA check's table, budgets and plot in the report; without the tools, the
    reason in their place."""
    from pyclpt.gpu.check import IsaReport
    from pyclpt.gpu.isa import KernelCost

    costs = [KernelCost("intersect", "intersect", t, r, 0, 256, 0, 0, s, s / m, None, ("cornell-box",))
             for t, r, s, m in (("sm_90", 47, 40, 64), ("gfx1030", 44, 16, 16), ("gfx90a", 60, 8, 8))]
    isa = IsaReport("LLVM 15", ["cornell-box"], 1, {"sm_90": 1, "gfx1030": 1, "gfx90a": 1}, costs).to_json()
    assert IsaReport.from_json(json.loads(json.dumps(isa))).costs == costs
    doc = document.Document("report")
    figure = plots_module().isa_occupancy({"isa": isa}, tmp_path)
    assert figure == "isa_occupancy.png" and (tmp_path / figure).stat().st_size > 0
    report._isa_section(doc, isa, {"isa_occupancy": figure})
    text = document.to_markdown(doc)
    assert "# GPU instruction sets" in text and "| intersect | 47 r, 256 B, 40 (62%) |" in text
    assert "intersect: 47 registers, 256 B stack on sm_90 (budget 96, 256 B: met)" in text
    assert "isa_occupancy.png" in text
    doc = document.Document("report")
    report._isa_section(doc, {"error": "the GPU ISA check needs libclc"}, {})
    assert "Not checked: the GPU ISA check needs libclc." in document.to_markdown(doc)
    assert "--isa" in report.build_parser().format_help()


def plots_module():
    try:
        from pyclpt.bench.report import plots
    except ModuleNotFoundError:
        from bench.report import plots
    return plots
