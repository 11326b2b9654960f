"""The house rules of docs/architecture.md that import-linter does not check.

* No module imports another module's private (underscore) name.
* The core install (no ``[synth]`` extra: no open3d, trimesh, embreex) imports and runs the
  jobs that do not render: the command lines, survey processing, masks, availability, the
  locator and reading a simulation. Checked by running them with those packages blocked.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SYNTH_ONLY = ("trimesh", "open3d", "embreex")

# Refuses the [synth] packages as if they were not installed, then runs the given code.
_BLOCKER = textwrap.dedent(
    """
    import importlib.abc, sys
    class _NoSynth(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in {blocked!r}:
                raise ModuleNotFoundError(f"No module named {{name!r}}", name=name.split(".")[0])
            return None
    sys.meta_path.insert(0, _NoSynth())
    """
)


def _run_without_synth(code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    src = _BLOCKER.format(blocked=SYNTH_ONLY) + textwrap.dedent(code)
    return subprocess.run([sys.executable, "-c", src], capture_output=True, text=True,
                          cwd=cwd, timeout=300)  # fmt: skip


def _modules() -> list[tuple[str, Path]]:
    out = []
    for pkg in ("predisat", "locator"):
        for path in sorted((REPO / pkg).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out.append((name, path))
    return out


def test_no_module_imports_a_private_name_of_another() -> None:
    offenders = []
    for name, path in _modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom) or node.module is None or node.level:
                continue
            if node.module.split(".")[0] not in ("predisat", "locator") or node.module == name:
                continue
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    offenders.append(f"{name} imports {node.module}.{alias.name}")
    assert offenders == []


def test_core_modules_import_without_the_renderer(tmp_path: Path) -> None:
    core = [
        "predisat.cli", "predisat.cli.app", "predisat.cli.demo", "predisat.availability.run",
        "predisat.availability.report", "predisat.reconstruct.batch",
        "predisat.reconstruct.evaluate",
        "predisat.masks.fileformat", "predisat.masks.truth", "predisat.gnss.ephemeris",
        "predisat.survey", "predisat.sky.segment", "predisat.track", "predisat.terrain",
        "locator", "locator.cli", "locator.run", "locator.sources", "locator.runio",
        "locator.errorfit", "locator.evaluate", "locator.sim.simfile", "locator.spp",
        "locator.odometry.fusion", "locator.odometry.confidence", "locator.balises.capture",
        "locator.balises.campaign", "locator.balises.command", "locator.balises.place_command",
    ]  # fmt: skip
    done = _run_without_synth(
        f"import importlib\nfor m in {core!r}:\n    importlib.import_module(m)\nprint('ok')\n",
        REPO,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "ok"


def test_core_jobs_run_without_the_renderer(tmp_path: Path) -> None:
    """Availability of a mask file and its export run; a rendering command says what to install."""
    from predisat.masks.fileformat import write_masks
    from predisat.masks.maskset import MaskSet
    from predisat.track import demo_track

    track = demo_track()
    ch = np.arange(4000.0, 4200.1, 20.0)
    masks = MaskSet.from_track(track, ch, np.full((ch.size, 72), 10.0), az_step_deg=5.0)
    path = write_masks(masks, tmp_path / "m.parquet")
    done = _run_without_synth(
        f"""
        import sys
        from predisat.cli import main
        code = main(["availability", "--masks", {str(path)!r}, "--out", {str(tmp_path / "a")!r},
                     "--start", "2020-06-25T06:00", "--end", "2020-06-25T07:00", "--step", "600",
                     "--quiet", "--scheduler", "serial"])
        assert code == 0, code
        code = main(["export", {str(path)!r}, "--format", "rtklib", "--chainage", "4100",
                     "--out", {str(tmp_path / "m.txt")!r}])
        assert code == 0, code
        assert main(["synth", "--from-km", "4", "--to-km", "4.1", "--out",
                     {str(tmp_path / "s")!r}, "--quiet"]) == 2
        assert "trimesh" not in sys.modules and "open3d" not in sys.modules
        print("ok")
        """,
        tmp_path,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().endswith("ok")
    assert "pip install 'predisat[synth]'" in done.stderr
    assert (tmp_path / "a" / "report.html").is_file() and (tmp_path / "m.txt").is_file()
