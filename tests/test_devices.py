"""A second CPU OpenCL implementation as a check: Intel's CPU runtime (``pip install ".[intel]"``) beside
PoCL. Its registration with the ICD loader (pyclpt/device/vendors.py), the ``intel`` selector, every
kernel of cl/ built and run on it, and its images against PoCL's: exactly equal within a device (tested
in test_wavefront.py over ``each_device``), within a tolerance across devices (different compilers and
math libraries may differ in the last bits)."""
from __future__ import annotations

import ast
import subprocess
import sys

import numpy as np
import pyopencl as cl
import pytest

import pyclpt
from pyclpt.common import env
from pyclpt.device import vendors
from pyclpt.device.context import DeviceError, list_devices
from scenes import material_zoo  # tests/ is on sys.path (conftest.py)

# importing pyclpt.device registers the runtime (import pyclpt alone loads nothing: its names are lazy)
CHILD = ("import pyclpt.device, os; print(os.environ.get('OCL_ICD_VENDORS', '')); "
         "print([d.platform.name.strip() for _, _, d in pyclpt.list_devices()])")


def child(**extra: str) -> list[str]:
    """Run CHILD in a fresh interpreter (the ICD loader reads OCL_ICD_VENDORS once per process)."""
    environ = env.child_environment()
    environ.pop("OCL_ICD_VENDORS", None)
    environ.update(extra)
    out = subprocess.run([sys.executable, "-c", CHILD], env=environ, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.splitlines()


def test_pocl_stays_first(device):
    """The registered Intel platform is listed after the loader's others: PoCL keeps its index (0:0, or 1:0
    behind another ICD of the environment's, such as the test extra's Oclgrind, whose file sorts first)."""
    names = [d.platform.name.strip() for _, _, d in list_devices()]
    pocl = next(k for k, n in enumerate(names) if n.lower().startswith("portable computing language"))
    assert vendors.INTEL_PLATFORM not in names[:pocl]
    assert all(n in ("Oclgrind",) for n in names[:pocl]), names
    assert pyclpt.get_device(f"{list_devices()[pocl][0]}:0").is_pocl and device.is_pocl


def test_intel_selector(intel_device):
    assert intel_device.is_intel_cpu and not intel_device.is_pocl
    assert vendors.register() in ("registered", "system", "user")
    names = [d.platform.name.strip() for _, _, d in list_devices()]
    assert "Portable Computing Language" in names and vendors.INTEL_PLATFORM in names  # together


def test_registration_in_a_fresh_process(tmp_path):
    if vendors.intel_library() is None:
        if env.flag("PYCLPT_REQUIRE_INTEL"):
            pytest.fail("PYCLPT_REQUIRE_INTEL=1 but intel-opencl-rt is not installed")
        pytest.skip("intel-opencl-rt is not installed")
    folder, platforms = child(PYCLPT_CACHE_DIR=str(tmp_path))
    assert folder.startswith(str(tmp_path / "opencl-vendors"))
    icd = (tmp_path / "opencl-vendors").glob("*/intel-cpu.icd")
    assert [p.read_text().strip() for p in icd] == [str(vendors.intel_library())]
    listed = [n for n in ast.literal_eval(platforms) if n != "Oclgrind"]  # (the test extra's ICD, if installed)
    assert listed == ["Portable Computing Language", vendors.INTEL_PLATFORM]


def test_a_users_vendors_folder_is_respected(tmp_path):
    """OCL_ICD_VENDORS set by the user: pyclpt writes nothing and changes nothing."""
    (tmp_path / "vendors").mkdir()
    folder, platforms = child(PYCLPT_CACHE_DIR=str(tmp_path / "cache"), OCL_ICD_VENDORS=str(tmp_path / "vendors"))
    assert folder == str(tmp_path / "vendors")
    assert vendors.INTEL_PLATFORM not in platforms
    assert not (tmp_path / "cache" / "opencl-vendors").exists()


def test_missing_intel_says_how_to_install(monkeypatch):
    monkeypatch.setattr(vendors, "state", "absent")
    from pyclpt.device import context

    monkeypatch.setattr(context, "_is_intel_cpu", lambda d: False)
    with pytest.raises(DeviceError, match=r'no Intel CPU OpenCL device: .*pip install "pyclpt\[intel\]"'):
        context._select("intel")


# -- the default device: the fastest installed (fake platform lists: no real GPU here) ----------------
class _FakePlatform:
    def __init__(self, name: str, kinds: list[str]) -> None:
        self.name = name
        self.devices = [_FakeDevice(self, kind, i) for i, kind in enumerate(kinds)]

    def get_devices(self) -> list:
        return self.devices


class _FakeDevice:
    def __init__(self, platform: _FakePlatform, kind: str, index: int) -> None:
        self.platform = platform
        self.type = {"gpu": cl.device_type.GPU, "cpu": cl.device_type.CPU}[kind]
        self.name = f"{kind} {index} of {platform.name}"


POCL = ("Portable Computing Language", ["cpu"])
INTEL = (vendors.INTEL_PLATFORM, ["cpu"])
GPU = ("NVIDIA CUDA", ["gpu"])


def _fake_platforms(monkeypatch, *platforms: tuple[str, list[str]]) -> None:
    fakes = [_FakePlatform(name, kinds) for name, kinds in platforms]
    monkeypatch.setattr(cl, "get_platforms", lambda: fakes)
    monkeypatch.delenv("PYCLPT_DEVICE", raising=False)


@pytest.mark.parametrize("platforms, expected, why", [
    ([POCL, INTEL, GPU], "NVIDIA CUDA", "GPU"),
    ([GPU, POCL], "NVIDIA CUDA", "GPU"),
    ([POCL, INTEL], vendors.INTEL_PLATFORM, "Intel's CPU runtime"),
    ([INTEL, POCL], vendors.INTEL_PLATFORM, "Intel's CPU runtime"),
    ([POCL], "Portable Computing Language", 'pip install "pyclpt[intel]"'),
    ([("Some CPU Vendor", ["cpu"])], "Some CPU Vendor", "the first device found"),
], ids=["gpu-intel-pocl", "gpu-pocl", "intel-pocl", "intel-first", "pocl", "other"])
def test_default_is_the_fastest_installed(monkeypatch, platforms, expected, why):
    """GPU > Intel's CPU runtime > PoCL, whatever the platforms' order."""
    from pyclpt.device import context

    _fake_platforms(monkeypatch, *platforms)
    chosen, reason = context.default_choice()
    assert chosen.platform.name == expected and why in reason
    assert context._select("") is chosen and context._select("default") is chosen


def test_pyclpt_device_wins_over_the_fastest(monkeypatch):
    from pyclpt.device import context

    _fake_platforms(monkeypatch, POCL, INTEL, GPU)
    monkeypatch.setenv("PYCLPT_DEVICE", "pocl")
    chosen, reason = context.default_choice()
    assert chosen.platform.name == "Portable Computing Language" and "PYCLPT_DEVICE='pocl'" in reason
    assert context._select("intel").platform.name == vendors.INTEL_PLATFORM  # --device wins too
    monkeypatch.setenv("PYCLPT_DEVICE", "no-such-device")
    with pytest.raises(DeviceError, match="PYCLPT_DEVICE='no-such-device' \\(the default device\\)"):
        context.default_choice()


def test_default_choice_is_logged_once(monkeypatch, caplog):
    from pyclpt.device import context

    _fake_platforms(monkeypatch, POCL, INTEL)
    opened = []

    class Opened:
        def __init__(self, dev) -> None:
            self.name = f"{dev.platform.name} / {dev.name}"
            opened.append(self)

    monkeypatch.setattr(context, "_default", None)
    monkeypatch.setattr(context, "_open", Opened)
    caplog.set_level("INFO", logger="pyclpt")
    first = context.default_device()
    assert context.default_device() is first and len(opened) == 1
    said = [r.getMessage() for r in caplog.records if r.name == "pyclpt"]
    assert said == [f"device: {vendors.INTEL_PLATFORM} / cpu 0 of {vendors.INTEL_PLATFORM} (no GPU; Intel's CPU "
                    f"runtime renders faster than PoCL on the same CPU)"]


def test_the_test_session_runs_on_pocl(device):
    """tests/conftest.py sets PYCLPT_DEVICE=pocl (unless already set), here and in the CLI's child processes:
    the suite stays on PoCL where Intel's runtime, the faster default, is installed."""
    if env.get("PYCLPT_DEVICE") != "pocl":
        pytest.skip(f"{env.describe('PYCLPT_DEVICE')} chosen for this session")
    assert device.is_pocl and pyclpt.default_device() is device
    listed = [n for n in ast.literal_eval(child()[1]) if n != "Oclgrind"]  # the child inherits the setting
    assert listed[0] == "Portable Computing Language"
    out = subprocess.run([sys.executable, "-c", "import pyclpt; print(pyclpt.default_device().name)"],
                         env=env.child_environment(), capture_output=True, text=True, timeout=120)
    assert out.stdout.startswith("Portable Computing Language"), out.stderr


@pytest.mark.parametrize("integrator,layout", [("megakernel", "soa"), ("wavefront", "soa"), ("wavefront", "aos")])
def test_intel_matches_pocl_cornell_box(cornell_box, device, intel_device, integrator, layout):
    """Every kernel the render uses (integrator, accumulation) builds and runs on Intel's runtime, and the
    image matches PoCL's within float rounding (the Cornell box: diffuse only, area light, depth 8; the
    megakernel crashed there before cl/scene/lights.h's env_eval kept its record index non-negative)."""
    kw = dict(spp=4, max_depth=8, width=32, height=32, seed=5, integrator=integrator, layout=layout, progress=False)
    pocl = pyclpt.render(cornell_box, device=device, **kw)
    intel = pyclpt.render(cornell_box, device=intel_device, **kw)
    assert pocl.max() > 0 and np.isfinite(intel).all()
    np.testing.assert_allclose(intel, pocl, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_intel_matches_pocl_rough_materials(shared_scenes, device, intel_device, integrator):
    """cornell-bunny: a rough conductor floor (visible-normal sampling) and a glass bunny, depth 8. With
    float3 code and a uint4 Philox, Intel's vectorizer sampled wrong directions in some lanes here and in
    the wavefront's sample_bsdf (docs/devices.md); the vectorized stages must agree with PoCL."""
    scene = pyclpt.load("cornell-bunny")
    kw = dict(spp=4, max_depth=8, width=32, height=32, seed=3, integrator=integrator, progress=False)
    pocl = pyclpt.render(scene, device=device, **kw)
    intel = pyclpt.render(scene, device=intel_device, **kw)
    assert pocl.max() > 0 and np.isfinite(intel).all()
    np.testing.assert_allclose(intel, pocl, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_intel_matches_pocl_every_material(device, intel_device, integrator):
    """Every material kind, textures, a bump map, a mask, a point light, a constant environment and an
    area light in one scene (tests/scenes.py: material_zoo), through the vectorized stages of Intel's
    runtime and through PoCL."""
    scene = material_zoo()
    kw = dict(spp=2, max_depth=6, width=32, height=32, seed=4, integrator=integrator, progress=False)
    pocl = pyclpt.render(scene, device=device, **kw)
    intel = pyclpt.render(scene, device=intel_device, **kw)
    assert pocl.max() > 0 and np.isfinite(intel).all()
    np.testing.assert_allclose(intel, pocl, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("precision", ["single", "compensated", "double"])
def test_accumulation_on_intel(cornell_box, intel_device, precision):
    """cl/film/accumulate.cl in every precision: the progressive average of 4 frames is the 4-spp render."""
    pr = pyclpt.ProgressiveRenderer(cornell_box, seed=2, width=16, height=16, max_depth=4, precision=precision,
                                    device=intel_device)
    pr.step(4)
    ref = pyclpt.render(cornell_box, spp=4, seed=2, width=16, height=16, max_depth=4, device=intel_device,
                        progress=False)
    np.testing.assert_allclose(pr.image(), ref, rtol=1e-5, atol=1e-6)
