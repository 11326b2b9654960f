"""Tests of predisat.reconstruct.batch on a tiny synthetic survey (160x120 pinhole, 60 m)."""

from __future__ import annotations

import csv
import io
import os
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from predisat.camera.models import CameraModel
from predisat.masks.fileformat import read_masks
from predisat.masks.maskset import BinSource, MaskError, MaskSet, concat_masksets
from predisat.reconstruct.badframes import BadFrameError
from predisat.reconstruct.batch import RunStopped, process_survey
from predisat.reconstruct.frames import default_segmenter
from predisat.reconstruct.params import PipelineParams
from tests.predisat.candidate_net import net_copy

ROOT = Path(__file__).resolve().parents[3]
CAM = CameraModel.pinhole_from_fov(160, 120, 74.0)
PARAMS = PipelineParams(chunk_m=30.0)  # 3 chunks over 3000..3060 m


class CountingSegmenter:
    """The default segmenter, counting its calls (in-process runs only)."""

    def __init__(self) -> None:
        self.calls: list[int] = []

    def __call__(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        self.calls.append(image.shape[1])
        return default_segmenter(image)


def blue_sky(image: np.ndarray) -> tuple[np.ndarray, None]:
    """A cheap module-level segmenter (picklable for worker processes)."""
    b, g, r = (image[..., k].astype(int) for k in range(3))
    return (b > r + 10) | ((b + g + r) > 600), None


@pytest.fixture(scope="module")
def survey_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    out = tmp_path_factory.mktemp("synth")
    generate_survey(
        demo_track(), 3000.0, 3060.0, sky="clear", seed=3, out_dir=out, camera=CAM,
        progress=False,
    )  # fmt: skip
    return out / "survey"


@pytest.fixture(scope="module")
def first_run(survey_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("run") / "masks"
    seg = CountingSegmenter()
    res = process_survey(survey_dir, out, PARAMS, progress=False, segmenter=seg)
    return out, (res, seg)


def _manifest(survey_dir: Path) -> list[dict[str, str]]:
    with open(survey_dir / "manifest.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_positions_are_the_distinct_frame_chainages(survey_dir: Path, first_run) -> None:
    out, (res, seg) = first_run
    rows = _manifest(survey_dir)
    want = np.unique([float(r["chainage_m"]) for r in rows])
    masks = read_masks(out / "masks.parquet")
    np.testing.assert_allclose(masks.chainage_m, want, atol=1e-3)
    assert masks.n_pos == 7 and res.masks.n_pos == 7
    # every frame segmented exactly once although the chunks' frame windows overlap
    assert len(seg.calls) == len(rows) == res.frames_segmented
    assert res.chunks_done == 3 and res.chunks_skipped == 0
    assert sorted(p.name for p in (out / "chunks").glob("*.parquet")) == [
        "3000_3030.parquet", "3030_3060.parquet", "3060_3090.parquet",
    ]  # fmt: skip
    assert masks.provenance["run_key"] and masks.provenance["survey_hash"]
    # a rendered survey says so in the masks (the availability report's synthetic banner)
    assert masks.provenance["survey_generator"] == "predisat.synth.generate"
    assert masks.provenance["survey_description"].startswith("synthetic survey, seed 3")
    assert np.all((masks.mask_el_deg >= 0) & (masks.mask_el_deg <= 90))
    assert res.bad_frames == ()


def test_resume_redoes_only_the_missing_chunk(first_run, survey_dir: Path, tmp_path) -> None:
    out0, (res0, _) = first_run
    out = tmp_path / "copy"
    shutil.copytree(out0, out)
    kept = {p.name: p.stat().st_mtime_ns for p in (out / "chunks").iterdir()}
    for suffix in (".json", ".parquet"):
        (out / "chunks" / f"3030_3060{suffix}").unlink()
        kept.pop(f"3030_3060{suffix}")
    seg = CountingSegmenter()
    res = process_survey(survey_dir, out, PARAMS, progress=False, segmenter=seg)
    assert (res.chunks_done, res.chunks_skipped) == (1, 2)
    assert seg.calls == []  # segmentation came from the cache
    for name, mtime in kept.items():
        assert (out / "chunks" / name).stat().st_mtime_ns == mtime, name
    assert (out / "chunks" / "3030_3060.json").is_file()
    np.testing.assert_array_equal(res.masks.mask_el_deg, res0.masks.mask_el_deg)
    np.testing.assert_array_equal(res.masks.source, res0.masks.source)


def test_resume_redoes_files_emptied_by_a_power_cut(first_run, survey_dir: Path, tmp_path) -> None:
    out0, (res0, _) = first_run
    out = tmp_path / "copy"
    shutil.copytree(out0, out)
    (out / "chunks" / "3060_3090.parquet").write_bytes(b"")  # renamed, data never flushed
    # a readable Parquet file holding other rows than its marker says (1 position, not 3)
    shutil.copy(out0 / "chunks" / "3060_3090.parquet", out / "chunks" / "3030_3060.parquet")
    # every chunk needs every frame of this 60 m survey, so any two cache entries are read
    cache = sorted((out / "cache").rglob("*.npz"))
    cache[0].write_bytes(b"")
    cache[1].write_bytes(cache[1].read_bytes()[:100])  # torn zip
    seg = CountingSegmenter()
    res = process_survey(survey_dir, out, PARAMS, progress=False, segmenter=seg)
    assert (res.chunks_done, res.chunks_skipped) == (2, 1)
    assert len(seg.calls) == 2  # the two damaged cache entries, recomputed
    np.testing.assert_array_equal(res.masks.mask_el_deg, res0.masks.mask_el_deg)


def test_interrupted_run_resumes(survey_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "masks"
    with pytest.raises(RunStopped):
        process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky,
                       max_chunks=1)  # fmt: skip
    assert len(list((out / "chunks").glob("*.json"))) == 1
    assert not (out / "masks.parquet").exists()
    res = process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky)
    assert (res.chunks_done, res.chunks_skipped) == (2, 1)
    assert res.frames_segmented == 0
    # changed parameters invalidate the finished chunks
    other = PipelineParams(chunk_m=30.0, segmenter="blue")
    res2 = process_survey(survey_dir, out, other, progress=False, segmenter=blue_sky)
    assert (res2.chunks_done, res2.chunks_skipped) == (3, 0)


@pytest.fixture(scope="module")
def dask_address() -> Any:
    """A cluster of two worker processes for the module's tests (each run would start its
    own otherwise): its scheduler's address."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as cluster:  # fmt: skip
        yield cluster.scheduler_address


def _outputs(out: Path) -> dict[str, bytes]:
    """Every file a run publishes (not the cache, not timings), by path."""
    files = [out / "masks.parquet", out / "bad_frames.csv", *sorted((out / "chunks").iterdir())]
    return {str(f.relative_to(out)): f.read_bytes() for f in files}


def dies_once(image: np.ndarray, marker: str) -> tuple[np.ndarray, None]:
    """blue_sky, but the first call anywhere kills its own process (SIGKILL) mid-task."""
    import os
    import signal

    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return blue_sky(image)
    os.close(fd)
    os.kill(os.getpid(), signal.SIGKILL)
    raise AssertionError("unreachable")


@pytest.mark.slow
def test_dask_cluster_writes_the_same_bytes_as_a_serial_run(
    survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dask_address: str
) -> None:
    """Any number of workers, a worker killed mid-task: the files are those of a serial run,
    byte for byte (timestamps pinned by SOURCE_DATE_EPOCH)."""
    import functools

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    p = PipelineParams(chunk_m=30.0, segmenter="blue")
    serial = process_survey(survey_dir, tmp_path / "a", p, progress=False, segmenter=blue_sky)
    want = _outputs(tmp_path / "a")
    assert len(want) == 2 + 2 * serial.chunks_done
    two = process_survey(survey_dir, tmp_path / "b", p, progress=False, segmenter=blue_sky,
                         scheduler=dask_address)  # fmt: skip
    assert two.chunks_done == serial.chunks_done and two.frames_segmented == 14
    assert _outputs(tmp_path / "b") == want
    # a worker killed by SIGKILL in its first task: the task runs again on another
    marker = tmp_path / "killed-once"
    seg = functools.partial(dies_once, marker=str(marker))
    one = process_survey(survey_dir, tmp_path / "c", p, progress=False, segmenter=seg,
                         scheduler=dask_address)  # fmt: skip
    assert marker.exists() and one.bad_frames == () and one.frames_segmented == 14
    assert _outputs(tmp_path / "c") == want


def test_a_relative_sky_net_reaches_the_workers(
    survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dask_address: str
) -> None:
    """A relative --sky-net was sent as it was: a worker, in its own working folder, failed
    every frame (a review). Made absolute in the client."""
    from predisat.sky.network import SkyNet

    net = SkyNet.default().path
    shutil.copy(net, tmp_path / "net.onnx")
    shutil.copy(net.with_suffix(".json"), tmp_path / "net.json")
    monkeypatch.chdir(tmp_path)  # the workers were started elsewhere
    p = PipelineParams(chunk_m=30.0, sky_net="net.onnx")
    res = process_survey(survey_dir, tmp_path / "out", p, progress=False, scheduler=dask_address)
    assert res.bad_frames == () and res.frames_segmented == 14


def test_a_second_run_into_the_same_folder_is_refused_at_once(
    survey_dir: Path, tmp_path: Path
) -> None:
    """Two runs on one --out did all the work twice and raced on its files (a user trial)."""
    import subprocess
    import sys

    from predisat.atomic import FolderInUseError, exclusive_folder

    out = tmp_path / "out"
    out.mkdir()
    # another process holds the folder (a lock is per process: flock)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from predisat.atomic import exclusive_folder\n"
         f"with exclusive_folder({str(out)!r}):\n print('held', flush=True); time.sleep(60)"],
        stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(FolderInUseError, match=rf"{out}: another run is writing there "
                           rf"\(process {holder.pid}, since .*another output folder"):  # fmt: skip
            process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky)
        assert not (out / "chunks").exists()  # nothing done
    finally:
        holder.kill()
        holder.wait()
    with exclusive_folder(out):  # released when its process ended
        pass


def test_serial_with_several_workers_is_refused(survey_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--scheduler local"):
        process_survey(survey_dir, tmp_path / "a", PARAMS, progress=False, scheduler="serial",
                       workers=2)  # fmt: skip
    assert not (tmp_path / "a").exists()  # refused before any work


def test_a_resumed_run_on_dask_redoes_only_missing_chunks(
    survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dask_address: str
) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    p = PipelineParams(chunk_m=30.0, segmenter="blue")
    process_survey(survey_dir, tmp_path / "a", p, progress=False, segmenter=blue_sky)
    with pytest.raises(RunStopped):
        process_survey(survey_dir, tmp_path / "b", p, progress=False, segmenter=blue_sky,
                       max_chunks=1)  # fmt: skip
    res = process_survey(survey_dir, tmp_path / "b", p, progress=False, segmenter=blue_sky,
                         scheduler=dask_address)  # fmt: skip
    assert (res.chunks_done, res.chunks_skipped) == (2, 1)
    assert _outputs(tmp_path / "b") == _outputs(tmp_path / "a")


def test_corrupt_image_is_reported_and_skipped(survey_dir: Path, tmp_path: Path) -> None:
    src = tmp_path / "survey"
    shutil.copytree(survey_dir, src)
    rows = _manifest(src)
    victim = rows[4]
    (src / victim["image"]).write_bytes(b"not a jpeg at all")
    out = tmp_path / "masks"
    res = process_survey(src, out, PARAMS, progress=False, segmenter=blue_sky)
    assert [b.frame_id for b in res.bad_frames] == [victim["frame_id"]]
    with open(out / "bad_frames.csv", newline="") as fh:
        listed = list(csv.DictReader(fh))
    assert [r["frame_id"] for r in listed] == [victim["frame_id"]]
    assert "decode" in listed[0]["message"]
    assert res.masks.n_pos == 7  # the position keeps its other frame
    with pytest.raises(BadFrameError, match=victim["frame_id"]):
        process_survey(src, tmp_path / "strict", PARAMS, progress=False, segmenter=blue_sky,
                       strict=True)  # fmt: skip


def test_a_survey_whose_every_frame_is_bad_makes_no_masks(survey_dir: Path, tmp_path: Path):
    """A user trial's run whose every frame was set aside published masks 100 % assumed and
    exited 0; it now stops before the reconstruction, saying why."""
    src = tmp_path / "survey"
    shutil.copytree(survey_dir, src)
    rows = _manifest(src)
    for r in rows:
        (src / r["image"]).write_bytes(b"not a jpeg at all")
    out = tmp_path / "masks"
    with pytest.raises(ValueError, match=rf"every one of its {len(rows)} frames was set aside "
                       rf"\({len(rows)} at stage segment; the first, "):  # fmt: skip
        process_survey(src, out, PARAMS, progress=False, segmenter=blue_sky)
    assert not (out / "masks.parquet").exists()


def _jpeg(shape: tuple[int, int], seed: int, **save: Any) -> bytes:
    from PIL import Image

    rng = np.random.default_rng(seed)
    pixels = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
    buf = io.BytesIO()
    Image.fromarray(pixels).save(buf, "JPEG", **save)
    return buf.getvalue()


def _pillow_decodes(data: bytes) -> bool:
    """Pillow, unlike libjpeg through OpenCV, refuses a truncated file: the independent check."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as im:
            im.load()
    except OSError:
        return False
    return True


@pytest.mark.parametrize("progressive", [False, True])
def test_truncated_jpeg_is_told_from_a_whole_one(progressive: bool, tmp_path: Path) -> None:
    import cv2

    from predisat.reconstruct.frames import truncation

    whole = _jpeg((120, 160), 3, quality=90, progressive=progressive)
    assert _pillow_decodes(whole) and truncation(whole) is None
    assert truncation(whole + bytes(500)) is None  # padding after the end marker
    sos = whole.index(b"\xff\xda")
    passed_by_opencv = 0
    for cut in np.linspace(sos + 20, len(whole) - 2, 7).astype(int):
        part = whole[:cut]
        assert not _pillow_decodes(part)
        assert truncation(part) is not None
        (tmp_path / "cut.jpg").write_bytes(part)
        passed_by_opencv += cv2.imread(str(tmp_path / "cut.jpg")) is not None
    assert passed_by_opencv > 0  # cv2.imread hands such files back, grey-filled: the reason
    assert "header" in str(truncation(whole[: sos - 4]))


def test_thumbnail_end_marker_does_not_hide_truncation() -> None:
    """An EXIF-style APP1 segment carrying a whole thumbnail JPEG (with its own end marker)
    before the frame's scan data."""
    whole = _jpeg((120, 160), 4, quality=90)
    thumb = _jpeg((16, 16), 5)
    body = b"Exif\x00\x00" + thumb
    app1 = b"\xff\xe1" + (len(body) + 2).to_bytes(2, "big") + body
    framed = whole[:2] + app1 + whole[2:]
    assert _pillow_decodes(framed)
    from predisat.reconstruct.frames import truncation

    assert truncation(framed) is None
    part = framed[: framed.index(b"\xff\xda") + 200]
    assert not _pillow_decodes(part) and truncation(part) is not None


def test_truncated_png_is_reported() -> None:
    import cv2

    from predisat.reconstruct.frames import truncation

    ok, enc = cv2.imencode(".png", np.random.default_rng(6).integers(0, 256, (60, 80, 3), np.uint8))
    data = enc.tobytes()
    assert ok and _pillow_decodes(data) and truncation(data) is None
    assert not _pillow_decodes(data[:-30]) and "IEND" in str(truncation(data[:-30]))


def test_truncated_frame_is_reported_and_skipped(
    survey_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "survey"
    shutil.copytree(survey_dir, src)
    victim = _manifest(src)[5]
    path = src / victim["image"]
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])  # a copy cut short
    out = tmp_path / "masks"
    res = process_survey(src, out, PARAMS, progress=False, segmenter=blue_sky)
    assert [b.frame_id for b in res.bad_frames] == [victim["frame_id"]]
    assert "truncated" in res.bad_frames[0].message
    # told even without progress output (--quiet): a skipped frame is never silent
    assert f"bad frame {victim['frame_id']}" in capsys.readouterr().err
    # the resumed run still names it, from the cache, without segmenting anything
    again = process_survey(src, out, PARAMS, progress=True, segmenter=blue_sky)
    assert again.frames_segmented == 0 and len(again.bad_frames) == 1
    assert f"bad frame {victim['frame_id']}" in (err := capsys.readouterr().err)
    assert "as in a run before" in err


def test_empty_image_is_reported_and_skipped(survey_dir: Path, tmp_path: Path) -> None:
    src = tmp_path / "survey"
    shutil.copytree(survey_dir, src)
    victim = _manifest(src)[3]
    (src / victim["image"]).write_bytes(b"")  # what a failed copy leaves
    res = process_survey(src, tmp_path / "masks", PARAMS, progress=False, segmenter=blue_sky)
    assert [b.frame_id for b in res.bad_frames] == [victim["frame_id"]]
    assert "empty (0 bytes)" in res.bad_frames[0].message


def test_fixed_frame_redoes_its_chunks_and_strict_checks_a_finished_folder(
    survey_dir: Path, tmp_path: Path
) -> None:
    clean = process_survey(survey_dir, tmp_path / "clean", PARAMS, progress=False,
                           segmenter=blue_sky)  # fmt: skip
    src = tmp_path / "survey"
    shutil.copytree(survey_dir, src)
    victim = _manifest(src)[5]
    path = src / victim["image"]
    good = path.read_bytes()
    path.write_bytes(good[: len(good) // 2])
    out = tmp_path / "masks"
    first = process_survey(src, out, PARAMS, progress=False, segmenter=blue_sky)
    assert [b.frame_id for b in first.bad_frames] == [victim["frame_id"]]
    # a --strict rerun on the finished folder must not pass over the frame skipped before
    with pytest.raises(BadFrameError, match=f"bad frame {victim['frame_id']}.*run before"):
        process_survey(src, out, PARAMS, progress=False, segmenter=blue_sky, strict=True)
    path.write_bytes(good)  # the frame copied again from the camera
    fixed = process_survey(src, out, PARAMS, progress=False, segmenter=blue_sky)
    assert fixed.bad_frames == () and fixed.frames_segmented == 1
    # each chunk reads the frames within overlap_m (315 m) of it: here every chunk reads them all
    assert PARAMS.reconstruction.overlap_m > 60.0
    assert fixed.chunks_done == first.chunks_done and fixed.chunks_skipped == 0
    np.testing.assert_array_equal(fixed.masks.mask_el_deg, clean.masks.mask_el_deg)
    np.testing.assert_array_equal(fixed.masks.source, clean.masks.source)
    again = process_survey(src, out, PARAMS, progress=False, segmenter=blue_sky, strict=True)
    assert again.chunks_done == 0 and again.bad_frames == ()


def test_concat_masksets_round_trip(first_run) -> None:
    _, (res, _) = first_run
    m: MaskSet = res.masks
    parts = [m.subset(m.chainage_m[0], m.chainage_m[2]), m.subset(m.chainage_m[3], 1e9)]
    back = concat_masksets(parts, provenance=m.provenance)
    assert back.equals(m)
    with pytest.raises(MaskError, match="strictly increasing"):
        concat_masksets(parts[::-1])
    coarse = MaskSet.from_arrays([0.0], [50.0], [4.0], [0.0], [0.0], np.zeros((1, 4)))
    with pytest.raises(MaskError, match="az_step_deg"):
        concat_masksets([parts[0], coarse])
    # a later part's survey warning or higher antenna is not dropped for the first's provenance
    for key, value in (("survey_beside_track", {"median_offset_m": 4.0}),
                       ("antenna_height_m", 5.0)):  # fmt: skip
        other = replace(parts[1], provenance={**parts[1].provenance, key: value})
        with pytest.raises(MaskError, match=key):
            concat_masksets([parts[0], other])
        assert concat_masksets([parts[0], other], provenance=m.provenance).equals(m)


def test_changed_code_redoes_chunks_and_segmentation(
    survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import predisat.reconstruct.batch as pl

    out = tmp_path / "masks"
    p = PipelineParams(chunk_m=30.0, segmenter="blue")
    first = process_survey(survey_dir, out, p, progress=False, segmenter=blue_sky)
    again = process_survey(survey_dir, out, p, progress=False, segmenter=blue_sky)
    assert (again.chunks_done, again.frames_segmented) == (0, 0)
    # a development install edits code without bumping the version: nothing stale is reused
    real = pl.code_fingerprint
    monkeypatch.setattr(pl, "code_fingerprint", lambda parts=None: "f" * 16 + real(parts))
    edited = process_survey(survey_dir, out, p, progress=False, segmenter=blue_sky)
    assert edited.chunks_done == 3 and edited.chunks_skipped == 0
    assert edited.frames_segmented == first.frames_segmented > 0
    assert len(list((out / "cache").iterdir())) == 2


def test_code_fingerprint_covers_the_named_files() -> None:
    from predisat.reconstruct.framecache import SEGMENTATION_CODE, code_fingerprint

    seg = code_fingerprint(SEGMENTATION_CODE)
    assert seg == code_fingerprint(SEGMENTATION_CODE)  # deterministic
    assert seg != code_fingerprint(["reconstruct/carving.py"]) != code_fingerprint()
    with pytest.raises(OSError):
        code_fingerprint(["no_such_module.py"])


def test_segmentation_fingerprint_covers_every_module_the_segmenters_import() -> None:
    """A module the segmentation runs but the fingerprint omits would let a stale cache stand
    after an edit (the network's module was missing until the ensemble became the default)."""
    import subprocess
    import sys

    from predisat.reconstruct.framecache import SEGMENTATION_CODE

    code = (
        "import sys, numpy as np\n"
        "from predisat.sky.segment import METHODS, SkyOptions, segment_sky\n"
        "img = (np.random.default_rng(0).random((60, 80, 3)) * 255).astype(np.uint8)\n"
        "for m in METHODS:\n"
        "    segment_sky(img, SkyOptions(method=m))\n"
        "import pathlib\n"
        "root = pathlib.Path(sys.modules['predisat'].__file__).parent\n"
        "print(' '.join(pathlib.Path(m.__file__).relative_to(root).as_posix()\n"
        "               for k, m in list(sys.modules.items()) if k.startswith('predisat.')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()  # fmt: skip
    files = set(out)
    assert "sky/network.py" in files  # the ensemble ran
    assert files <= set(SEGMENTATION_CODE)


def test_segmenter_name_must_be_a_method_unless_a_function_is_given(
    survey_dir: Path, tmp_path: Path
) -> None:
    with pytest.raises(ValueError, match="segmenter"):
        process_survey(survey_dir, tmp_path / "a", PipelineParams(segmenter="magic"),
                       progress=False)
    res = process_survey(survey_dir, tmp_path / "b", PipelineParams(chunk_m=30.0,
                         segmenter="magic"), progress=False, segmenter=blue_sky)
    assert res.masks.n_pos > 0


def test_segmenter_method_selects_the_segmentation(survey_dir: Path, tmp_path: Path) -> None:
    """Two methods give two caches and two provenance records; both give masks."""
    import json

    for method in ("learned", "ensemble"):
        res = process_survey(survey_dir, tmp_path / method,
                             PipelineParams(chunk_m=30.0, segmenter=method), progress=False)
        assert res.masks.n_pos > 0
        assert any(p.name.startswith(f"seg-{method}-")
                   for p in (tmp_path / method / "cache").iterdir())
        prov = json.loads((tmp_path / method / "provenance.json").read_text())
        assert method in json.dumps(prov)


def test_cache_entries_read_back_as_written_old_entries_too(tmp_path: Path) -> None:
    """Entries are deflated at level 1 since 2026-12-03 (np.savez_compressed before): the
    reader gets the same arrays from both."""
    import io
    import json

    from predisat.reconstruct.framecache import CACHE_VERSION, FrameJob, read_cache, write_cache

    image = tmp_path / "f.jpg"
    image.write_bytes(b"an image")
    job = FrameJob("f", str(image), 37, 5, str(tmp_path / "f.npz"))
    rng = np.random.default_rng(0)
    sky = rng.random((5, 37)) < 0.5
    conf = rng.random(37).astype(np.float32)
    write_cache(job, (sky, conf), None)
    got = read_cache(job)
    assert isinstance(got, tuple) and got[0].dtype == bool and got[1] is not None
    assert np.array_equal(got[0], sky) and np.array_equal(got[1], conf)
    with np.load(job.cache_path) as z:
        assert sorted(z.files) == ["confidence", "meta", "sky"]
        meta = json.loads(str(z["meta"]))
    old = io.BytesIO()
    np.savez_compressed(old, meta=np.array(json.dumps(meta)), sky=np.packbits(sky.ravel()),
                        confidence=conf)  # fmt: skip
    Path(job.cache_path).write_bytes(old.getvalue())
    again = read_cache(job)
    assert meta["version"] == CACHE_VERSION and isinstance(again, tuple)
    assert np.array_equal(again[0], sky) and again[1] is not None
    assert np.array_equal(again[1], conf)


def test_sky_net_is_used_recorded_and_keyed(survey_dir: Path, tmp_path: Path) -> None:
    import json

    from predisat.reconstruct.framecache import sky_net_sha256

    base = process_survey(survey_dir, tmp_path / "base", PipelineParams(chunk_m=30.0),
                          progress=False)
    same = net_copy(tmp_path / "same")
    out = tmp_path / "cand"
    res = process_survey(survey_dir, out, PipelineParams(chunk_m=30.0, sky_net=str(same)),
                         progress=False)
    # the shipped network from another file: the same masks, the file in the provenance
    np.testing.assert_array_equal(res.masks.mask_el_deg, base.masks.mask_el_deg)
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["params"]["sky_net"]["sha256"] == sky_net_sha256(same)
    assert "sky_net" not in json.loads((tmp_path / "base" / "provenance.json").read_text())[
        "params"]
    # another network into the same folder: nothing of the first is reused
    other = net_copy(tmp_path / "other", input_px=96)
    assert sky_net_sha256(other) != sky_net_sha256(same)
    again = process_survey(survey_dir, out, PipelineParams(chunk_m=30.0, sky_net=str(other)),
                           progress=False)
    assert again.chunks_skipped == 0 and again.frames_segmented == res.frames_segmented > 0
    # and it is the network that runs: at another input size the masks change
    assert not np.array_equal(again.masks.mask_el_deg, res.masks.mask_el_deg)
    assert len([p for p in (out / "cache").iterdir() if p.name.startswith("seg-ensemble-")]) == 2


def test_switching_the_thin_width_back_reuses_the_first_segmentation(
    survey_dir: Path, tmp_path: Path
) -> None:
    """A cache entry holds one thin width; each width keeps its own folder, so trying another
    width and going back segments nothing again (a user trial: every switch re-segmented)."""
    out = tmp_path / "out"
    first = process_survey(survey_dir, out, PipelineParams(chunk_m=30.0), progress=False)
    other = process_survey(survey_dir, out, PipelineParams(chunk_m=30.0, thin_deg=1.4),
                           progress=False)  # fmt: skip
    back = process_survey(survey_dir, out, PipelineParams(chunk_m=30.0), progress=False)
    assert first.frames_segmented > 0 and other.frames_segmented == first.frames_segmented
    assert back.frames_segmented == 0
    np.testing.assert_array_equal(back.masks.mask_el_deg, first.masks.mask_el_deg)


def test_sky_net_errors_name_the_file_and_the_fix(survey_dir: Path, tmp_path: Path) -> None:
    from predisat.cli.app import main

    with pytest.raises(ValueError, match="--segmenter ensemble"):
        PipelineParams(segmenter="learned", sky_net="x.onnx")
    missing = tmp_path / "missing.onnx"
    with pytest.raises(FileNotFoundError, match=r"missing\.onnx"):
        process_survey(survey_dir, tmp_path / "o", PipelineParams(sky_net=str(missing)),
                       progress=False)
    assert main(["process", str(survey_dir), "--out", str(tmp_path / "c"), "--quiet",
                 "--sky-net", str(missing)]) == 2


def test_thin_structure_policy_is_an_angle_per_camera(
    survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import predisat.reconstruct.batch as pl

    seen: list[int | None] = []

    def recording(image: np.ndarray, method=None, sky_net=None, thin_px=None):
        seen.append(thin_px)
        return blue_sky(image)

    monkeypatch.setattr(pl, "default_segmenter", recording)
    px_deg = np.degrees(2.0 * np.arctan(0.5 / CAM.fx))  # the test camera's centre pixel
    for thin_deg in (0.7, 2.0 * px_deg, 0.0):
        seen.clear()
        p = PipelineParams(chunk_m=30.0, thin_deg=thin_deg)
        res = process_survey(survey_dir, tmp_path / "out", p, progress=False)
        # every frame segmented again with the new width: the cache does not mix widths
        assert len(seen) == res.frames_segmented == len(_manifest(survey_dir))
        want = 0 if thin_deg == 0 else max(1, round(thin_deg / px_deg))
        assert set(seen) == {want}
    assert want == 0 and PipelineParams(thin_deg=2.0 * px_deg).thin_px(CAM) == 2
    # a barrel pinhole's pixels near its sides are 31 % wider than its centre's: the width follows
    # the widest, so no feature much wider than thin_deg is transparent anywhere in the frame
    barrel = CameraModel.pinhole_from_fov(640, 480, 74.0, dist=(-0.4, 0.12, 0.0, 0.0, 0.0))
    n_px = PipelineParams(thin_deg=0.7).thin_px(barrel)
    assert round(0.7 / barrel.centre_pixel_deg) == 5 and n_px == 4
    assert n_px * barrel.widest_pixel_deg <= 0.7 + barrel.widest_pixel_deg / 2
    with pytest.raises(ValueError, match="thin_deg"):
        PipelineParams(thin_deg=-1.0)


def test_a_hole_in_the_survey_is_closed_not_covered_by_neighbours(
    survey_dir: Path, first_run, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # both frames at 3030 m dropped from the manifest: a camera dropout between 3020 and 3040
    src = tmp_path / "survey"
    shutil.copytree(survey_dir, src)
    rows = _manifest(src)
    kept = [r for r in rows if float(r["chainage_m"]) != 3030.0]
    assert len(kept) == len(rows) - 2
    with open(src / "manifest.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(kept)
    capsys.readouterr()
    res = process_survey(src, tmp_path / "masks", PARAMS, progress=False, segmenter=blue_sky)
    err = capsys.readouterr().err
    assert "1 hole(s)" in err and "3020-3040 m" in err
    masks = read_masks(tmp_path / "masks" / "masks.parquet")
    np.testing.assert_allclose(masks.chainage_m, first_run[1][0].masks.chainage_m, atol=1e-3)
    i = int(np.argmin(np.abs(masks.chainage_m - 3030.0)))
    assert np.all(masks.mask_el_deg[i] == 90.0)
    assert np.all(masks.source[i] == BinSource.ASSUMED)
    assert masks.provenance["gaps_closed_m"] == [[3020.0, 3040.0]]
    # nothing is trusted in the hole, even at 89 deg; at the surveyed neighbours sky still is
    az = np.arange(0.0, 360.0, 15.0)
    assert not masks.trusted(np.full_like(az, 3030.0), az, 89.0).any()
    assert masks.trusted(np.full_like(az, 3010.0), az, 89.0).any()
    # the surveyed positions keep the masks their chunks computed
    chunks = concat_masksets([read_masks(p) for p in sorted((tmp_path / "masks" / "chunks")
                                                            .glob("*.parquet"))])  # fmt: skip
    surveyed = np.array([k for k in range(masks.n_pos) if k != i])
    np.testing.assert_array_equal(chunks.chainage_m, masks.chainage_m[surveyed])
    np.testing.assert_array_equal(chunks.mask_el_deg, masks.mask_el_deg[surveyed])
    # the hole's position lies on the track like the others
    full = first_run[1][0].masks
    np.testing.assert_allclose(masks.lat_deg[i], full.lat_deg[i], atol=1e-7)
    np.testing.assert_allclose(masks.heading_deg[i], full.heading_deg[i], atol=1e-3)
    assert res.bad_frames == ()


class RecordingSegmenter:
    """:func:`blue_sky`, recording each image it is given (in-process runs only)."""

    def __init__(self) -> None:
        self.images: list[np.ndarray] = []

    def __call__(self, image: np.ndarray) -> tuple[np.ndarray, None]:
        self.images.append(image.copy())
        return blue_sky(image)


def _zero_mid(data: bytes, n_bytes: int = 3000) -> bytes:
    """``data`` with ``n_bytes`` zeroed in the middle of its scan (a damaged copy)."""
    sos = data.index(b"\xff\xda")
    mid = max(sos + 40, (sos + len(data)) // 2 - n_bytes // 2)
    n_bytes = min(n_bytes, len(data) - 2 - mid)
    return data[:mid] + bytes(n_bytes) + data[mid + n_bytes :]


def test_jpeg_zeroed_inside_is_corrupt_although_opencv_and_pillow_decode_it() -> None:
    import cv2

    from predisat.reconstruct.frames import jpeg_corruption, truncation

    whole = (Path(__file__).parents[2] / "data/sky_synth/cloudy_right_000012.jpg").read_bytes()
    hurt = _zero_mid(whole)
    assert len(hurt) == len(whole) and truncation(hurt) is None  # the end marker is there
    assert cv2.imdecode(np.frombuffer(hurt, np.uint8), cv2.IMREAD_COLOR) is not None
    assert _pillow_decodes(hurt)  # Pillow too: libjpeg only warns on stderr
    assert jpeg_corruption(whole) is None
    assert "Corrupt JPEG data" in str(jpeg_corruption(hurt))
    assert jpeg_corruption(b"\x89PNG\r\n\x1a\n") is None  # not a JPEG: not its business


def test_jpeg_header_overwritten_is_damaged_not_truncated(tmp_path: Path) -> None:
    from predisat.reconstruct.frames import read_image

    whole = _jpeg((120, 160), 8, quality=90)
    path = tmp_path / "f.jpg"
    path.write_bytes(whole[:20] + bytes(200) + whole[220:])  # zeros over the header
    img, problem = read_image(str(path))
    assert img is None and f"image {path} is damaged (no JPEG marker at byte" in str(problem)


def test_blank_image_kinds() -> None:
    from predisat.reconstruct.frames import blank_image

    rng = np.random.default_rng(1)
    assert "all black" in str(blank_image(np.zeros((120, 160, 3), np.uint8)))
    assert "all white" in str(blank_image(np.full((120, 160, 3), 255, np.uint8)))
    noisy_grey = np.clip(128 + rng.normal(0, 0.5, (120, 160, 3)), 0, 255).astype(np.uint8)
    assert "one flat grey" in str(blank_image(noisy_grey))
    scene = np.zeros((120, 160, 3), np.uint8)
    scene[:40] = 200  # a skyline: sky above, ground below
    assert blank_image(scene) is None


def test_corrupt_and_implausible_frames_are_caught(
    survey_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each class of bad frame injected into one survey: each reported with its reason, file
    and manifest line, none given to the segmenter."""
    src = tmp_path / "survey"
    shutil.copytree(survey_dir, src)
    rows = _manifest(src)  # manifest line = index + 2
    white = cv2_encode(np.full((120, 160, 3), 255, np.uint8))
    black = cv2_encode(np.zeros((120, 160, 3), np.uint8))
    injected = {  # frame index -> (reason expected, new bytes or None for the manifest edit)
        1: ("corrupt inside", _zero_mid((src / rows[1]["image"]).read_bytes(), 1500)),
        3: ("all black", black),
        4: ("all white", white),
        # frozen: right_000003 holds right_000002's picture
        7: ("frozen: the same file", (src / rows[5]["image"]).read_bytes()),
        # frozen again: right_000005 is right_000004's picture re-encoded (other bytes)
        11: ("frozen: the same picture re-encoded", _reencode(src / rows[9]["image"], 80)),
        10: ("goes back in time", None),
        12: ("contradicts the run", None),
    }
    for i, (_, data) in injected.items():
        if data is not None:
            (src / rows[i]["image"]).write_bytes(data)
    rows[10]["gps_s"] = str(float(rows[8]["gps_s"]) - 0.5)  # left_000005 before left_000004
    rows[12]["chainage_m"] = "3900.0"  # left_000006: 840 m on from 3060 m in 0.8 s
    rows[12]["lat_deg"] = rows[12]["lon_deg"] = rows[12]["h_m"] = ""
    with open(src / "manifest.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    # left_000006 is the last left frame: the two before it agree, it does not
    seg = RecordingSegmenter()
    out = tmp_path / "masks"
    res = process_survey(src, out, PARAMS, progress=False, segmenter=seg)
    err = capsys.readouterr().err
    by_id = {b.frame_id: b for b in res.bad_frames}
    assert sorted(by_id) == sorted(rows[i]["frame_id"] for i in injected)  # 100 %, nothing else
    for i, (reason, data) in injected.items():
        b = by_id[rows[i]["frame_id"]]
        assert reason in b.message, b
        assert f"manifest line {i + 2}" in b.message, b
        if data is not None:
            assert rows[i]["image"] in b.message  # the file
        assert f"bad frame {rows[i]['frame_id']}" in err  # what the user sees
    assert "frame before ('right_000002', manifest line 7)" in by_id[rows[7]["frame_id"]].message
    # none of them reached the segmenter: every image it got is a good one
    from predisat.reconstruct.frames import blank_image

    assert len(seg.images) == len(rows) - len(injected)
    assert all(blank_image(im) is None for im in seg.images)
    with open(out / "bad_frames.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == len(injected)
    # and --strict stops at one of them
    with pytest.raises(BadFrameError, match="bad frame"):
        process_survey(src, tmp_path / "strict", PARAMS, progress=False, segmenter=blue_sky,
                       strict=True)  # fmt: skip


def _reencode(path: Path, quality: int) -> bytes:
    import cv2

    ok, enc = cv2.imencode(".jpg", cv2.imread(str(path)), [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok and enc.tobytes() != path.read_bytes()
    return enc.tobytes()


def cv2_encode(pixels: np.ndarray) -> bytes:
    import cv2

    ok, enc = cv2.imencode(".jpg", pixels)
    assert ok
    return enc.tobytes()


def test_png_zeroed_inside_is_refused_by_its_checksums(tmp_path: Path) -> None:
    import cv2

    from predisat.reconstruct.frames import read_image

    pixels = np.random.default_rng(7).integers(0, 256, (120, 160, 3), np.uint8)
    ok, enc = cv2.imencode(".png", pixels)
    assert ok
    data = enc.tobytes()
    mid = len(data) // 2
    path = tmp_path / "f.png"
    path.write_bytes(data[:mid] + bytes(3000) + data[mid + 3000 :])
    img, problem = read_image(str(path))
    assert img is None and "cannot be decoded" in str(problem) and str(path) in str(problem)


def test_elevation_tiles_raise_the_merged_masks_without_redoing_a_chunk(
    first_run, survey_dir: Path, tmp_path: Path, capsys
) -> None:
    import shutil

    import rasterio
    from rasterio.transform import from_origin

    from predisat.masks.maskset import BinSource
    from predisat.terrain import Dem
    from predisat.track.map import demo_track

    lat0, lon0, _ = demo_track().position_at(3030.0)
    cell = 1.0 / 1200.0

    def wall(name: str, half_lat_deg: float, half_lon_deg: float) -> Path:
        """Flat ground, and a 500 m wall from 1 km east of the line (0.0141 deg at 50.5 N),
        across the track (along it the small pinhole survey saw nothing: 90 deg)."""
        n_lat, n_lon = int(2 * half_lat_deg / cell) + 1, int(2 * half_lon_deg / cell) + 1
        lats = lat0 + half_lat_deg - np.arange(n_lat) * cell
        lons = lon0 - half_lon_deg + np.arange(n_lon) * cell
        z = np.where(lons[None, :] > lon0 + 0.0141, 500.0, 0.0) + 0.0 * lats[:, None]
        tif = tmp_path / name
        with rasterio.open(tif, "w", driver="GTiff", height=n_lat, width=n_lon, count=1,
                           dtype="float32", crs="EPSG:4326",
                           transform=from_origin(lons[0] - cell / 2, lats[0] + cell / 2, cell,
                                                 cell)) as ds:  # fmt: skip
            ds.write(z.astype(np.float32), 1)
        return tif

    out = tmp_path / "masks"
    shutil.copytree(first_run[0], out)
    before = first_run[1][0].masks
    east = int(np.argmin(np.abs(before.az_deg - 90.0)))
    low = before.mask_el_deg[:, east] < 20.0  # bins the cameras read below the wall
    assert low.any()
    # a tile of 3 x 4 km: every ray leaves it before the 25 km of the far field, so the wall
    # raises the bins but does not bound them (the terrain beyond may stand higher)
    res = process_survey(survey_dir, out, PARAMS, progress=True, segmenter=CountingSegmenter(),
                         dem=Dem.from_files([wall("small.tif", 0.03, 0.03)]))  # fmt: skip
    assert res.chunks_done == 0  # the terrain is applied at the merge
    assert np.all(res.masks.mask_el_deg[low, east] > 25.0)
    assert not np.any(res.masks.source == BinSource.TERRAIN)
    assert "not flagged TERRAIN" in capsys.readouterr().err
    # tiles reaching 25 km every way: the wall bounds the bins
    res = process_survey(survey_dir, out, PARAMS, progress=True, segmenter=CountingSegmenter(),
                         dem=Dem.from_files([wall("wall.tif", 0.25, 0.37)]))  # fmt: skip
    assert res.chunks_done == 0
    assert np.all(res.masks.source[low, east] == BinSource.TERRAIN)
    # the wall about 1 km away, 500 m + 16 m of stated error over an antenna 4 m above flat
    # ground: about atan(512 / 1000) = 27 deg
    assert np.all(res.masks.mask_el_deg[low, east] > 25.0)
    assert np.all(res.masks.mask_el_deg >= before.mask_el_deg)  # never lowered
    assert res.masks.provenance["terrain"]["raised_bins"] > 0
    err = capsys.readouterr().err
    assert "mask bins:" in err and "% terrain" in err
    # without tiles the same folder merges back to the plain masks
    plain = process_survey(survey_dir, out, PARAMS, progress=False,
                           segmenter=CountingSegmenter())  # fmt: skip
    assert np.array_equal(plain.masks.mask_el_deg, before.mask_el_deg)
    assert np.array_equal(plain.masks.source, before.source)
    assert "terrain" not in plain.masks.provenance


def test_source_report_warns_where_a_stretch_is_mostly_assumed() -> None:
    from predisat.masks.maskset import BinSource, MaskSet
    from predisat.reconstruct.batch import source_report

    n, n_az = 60, 36
    src = np.zeros((n, n_az), np.uint8)
    src[25:45] = BinSource.ASSUMED  # 200-440 m: the stretch 200-400 m is all assumed
    m = MaskSet(chainage_m=np.arange(n) * 10.0, lat_deg=np.full(n, 50.0),
                lon_deg=np.full(n, 4.0), h_m=np.zeros(n), heading_deg=np.zeros(n),
                az_step_deg=10.0, mask_el_deg=np.full((n, n_az), 4.0), source=src,
                margin_deg=np.zeros((n, n_az)))  # fmt: skip
    lines = source_report(m)
    assert lines[0].startswith("mask bins:") and "33.3 % assumed" in lines[0]
    warned = [ln for ln in lines if ln.startswith("warning")]
    assert len(warned) == 1 and "chainage 200-400 m" in warned[0]
    # the same stretch in a tunnel of the track: said to be one, no advice to survey again
    import dataclasses

    from predisat.track.map import demo_track

    track = demo_track()
    tunnel = dataclasses.replace(track, tunnels_m=((150.0, 450.0),))
    lines = source_report(m, track=tunnel)
    assert not [ln for ln in lines if ln.startswith("warning")]
    said = [ln for ln in lines if "in a tunnel" in ln]
    assert len(said) == 1 and said[0].startswith("chainage 200-400 m") and "--dem" not in said[0]
    # a user trial: the advice to give --dem when tiles were given, and no word that the map
    # tags no tunnel (it had lost them on the way)
    (warned,) = [ln for ln in source_report(m, track=track) if ln.startswith("warning")]
    assert "give elevation tiles (--dem)" in warned and "tags no tunnel" in warned
    dem = dataclasses.replace(m, provenance={"terrain": {"source": "N43E007.hgt"}})
    (warned,) = [ln for ln in source_report(dem) if ln.startswith("warning")]
    assert "--dem" not in warned and "the elevation tiles given bound none" in warned


def test_source_report_warns_where_the_observed_horizon_stands_above_the_assumed_one() -> None:
    """A valley: the cameras see no skyline under 9-10 deg, and the bins no camera saw rest on
    the assumed 5 deg (a user trial's Var valley world trusted 0.097 % of them falsely without
    elevation tiles, and nothing said so)."""
    from predisat.masks.maskset import BinSource, MaskSet
    from predisat.reconstruct.batch import source_report

    n, n_az = 20, 36
    rng = np.random.default_rng(2)

    def masks(observed_deg: float, terrain: bool = False) -> MaskSet:
        el = observed_deg + rng.uniform(0.0, 6.0, (n, n_az))
        src = np.zeros((n, n_az), np.uint8)
        src[:, :2] = BinSource.ASSUMED
        el[:, :2] = 5.0
        if terrain:
            src[:, 2] = BinSource.TERRAIN
        return MaskSet(chainage_m=np.arange(n) * 10.0, lat_deg=np.full(n, 50.0),
                       lon_deg=np.full(n, 4.0), h_m=np.zeros(n), heading_deg=np.zeros(n),
                       az_step_deg=10.0, mask_el_deg=el, source=src,
                       margin_deg=np.zeros((n, n_az)))  # fmt: skip

    valley = [ln for ln in source_report(masks(9.0)) if "horizon" in ln]
    assert len(valley) == 1 and valley[0].startswith("warning: the cameras saw no horizon")
    assert "above the 5 deg" in valley[0] and "--dem" in valley[0]
    assert not [ln for ln in source_report(masks(2.0)) if "horizon" in ln]  # flat land
    # with elevation tiles, bins left assumed at the default still stand under the observed
    # horizon: the tiles do not see walls or cuttings just beyond the corridor (a user trial's
    # canyon: a rock wall 250-300 m behind the train, 0.118 % of the assumed bins trusted
    # falsely with --dem, and the warning silenced)
    (tiles,) = [ln for ln in source_report(masks(9.0, terrain=True)) if "horizon" in ln]
    assert tiles.startswith("warning") and "--dem" not in tiles and "--calibrate" in tiles
    # every assumed bin raised above the default by the tiles: nothing to say
    raised = masks(9.0, terrain=True)
    raised = replace(raised, mask_el_deg=np.where(
        raised.source == BinSource.ASSUMED, 12.0, raised.mask_el_deg))
    assert not [ln for ln in source_report(raised) if "horizon" in ln]


def test_masks_name_the_rig_that_made_them(first_run) -> None:
    from predisat.availability.run import rig_text

    prov = first_run[1][0].masks.provenance
    assert set(prov["rig"]) == {"left", "right"}
    text = rig_text(prov)
    # the survey's cameras: the test's 160 x 120 pinhole on both sides, pitched 45 deg
    assert text.count("pinhole 160x120 px") == 2 and "pitch 45 deg" in text
    assert rig_text({}) == ""


def test_cache_keeps_the_thin_structure_pixels(tmp_path: Path) -> None:
    """A segmenter's third output (thin-structure pixels) survives the cache, bit for bit;
    an entry without it reads as None."""
    from predisat.reconstruct.framecache import FrameJob, read_cache, write_cache

    image = tmp_path / "f.jpg"
    image.write_bytes(b"an image")
    job = FrameJob("f", str(image), 37, 5, str(tmp_path / "f.npz"))
    rng = np.random.default_rng(1)
    sky = rng.random((5, 37)) < 0.5
    thin = sky & (rng.random((5, 37)) < 0.3)
    write_cache(job, (sky, None, thin), None)
    got = read_cache(job)
    assert isinstance(got, tuple) and got[2] is not None and got[2].dtype == bool
    assert np.array_equal(got[0], sky) and np.array_equal(got[2], thin) and got[1] is None
    write_cache(job, (sky, None), None)
    again = read_cache(job)
    assert isinstance(again, tuple) and again[2] is None


def test_a_survey_whose_every_frame_is_refused_says_why(survey_dir: Path, tmp_path) -> None:
    bad = tmp_path / "survey"
    shutil.copytree(survey_dir, bad)
    rows = _manifest(bad)
    for r in rows:  # a roll without its pitch: each frame refused
        r["roll_deg"], r["pitch_deg"] = "1.0", ""
    with open(bad / "manifest.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    with pytest.raises(ValueError, match=r"every frame was refused .*roll_deg and pitch_deg"):
        process_survey(bad, tmp_path / "out", PARAMS, progress=False)


def test_the_report_says_what_the_far_field_rests_on() -> None:
    from predisat.availability.run import far_field_text
    from predisat.masks.maskset import BinSource, MaskSet

    n, n_az = 4, 36
    src = np.zeros((n, n_az), np.uint8)
    src[:, :9] = BinSource.ASSUMED

    def masks(prov: dict) -> MaskSet:
        return MaskSet(chainage_m=np.arange(n) * 10.0, lat_deg=np.full(n, 50.0),
                       lon_deg=np.full(n, 4.0), h_m=np.zeros(n), heading_deg=np.zeros(n),
                       az_step_deg=10.0, mask_el_deg=np.full((n, n_az), 5.0), source=src,
                       margin_deg=np.zeros((n, n_az)), provenance=prov)  # fmt: skip

    made = masks({"params": {"reconstruction": {"far_default_deg": 5.0}}})
    assert far_field_text(made) == (
        "assumed at 5° where no camera saw it (25.0 % of the bins assumed: 0.0 % closed to the "
        "zenith, 25.0 % open); no elevation tiles given"
    )
    # tiles named, but no bin flagged TERRAIN: they may not cover the line
    raised = masks({"terrain": {"dem": ["N43E006.hgt"]}})
    assert "no bin rests on them (do they cover the line?)" in far_field_text(raised)
    src[:, 9:12] = BinSource.TERRAIN
    raised = masks({"terrain": {"dem": ["N43E006.hgt"]}})
    assert far_field_text(raised).startswith("raised to the elevation tiles ['N43E006.hgt'] in "
                                             "8.3 % of the bins")  # fmt: skip
    # flags the provenance does not explain (an edited file): said, not hidden
    assert far_field_text(masks({})).startswith("8.3 % of the bins flagged TERRAIN, but")
    src[:, 9:12] = BinSource.OBSERVED
    assert far_field_text(masks({})).startswith("25.0 % of the bins assumed")
    src[:] = BinSource.OBSERVED
    assert far_field_text(masks({})) == ""  # true masks: nothing to say


def test_the_report_warns_when_much_of_the_trusted_sky_is_assumed() -> None:
    """A user trial flagged every bin ASSUMED and got the surveyed file's figures, said in one
    header row only."""
    from predisat.availability.run import assumed_sky_notes
    from predisat.masks.maskset import BinSource, MaskSet

    n, n_az = 4, 100
    src = np.zeros((n, n_az), np.uint8)
    el = np.full((n, n_az), 10.0)
    el[:, :50] = 90.0  # closed: nothing trusted there, assumed or not
    src[:, :50] = BinSource.ASSUMED
    src[:, 50:52] = BinSource.ASSUMED  # 2 of the 50 open bins: 4 %

    def masks() -> MaskSet:
        return MaskSet(chainage_m=np.arange(n) * 10.0, lat_deg=np.full(n, 50.0),
                       lon_deg=np.full(n, 4.0), h_m=np.zeros(n), heading_deg=np.zeros(n),
                       az_step_deg=3.6, mask_el_deg=el, source=src,
                       margin_deg=np.zeros((n, n_az)))  # fmt: skip

    assert assumed_sky_notes(masks()) == []
    src[:, 52:54] = BinSource.ASSUMED  # 8 %
    (note,) = assumed_sky_notes(masks())
    assert note.startswith("8.0 % of the directions these masks leave open rest on an assumption")


def test_process_says_when_a_pair_of_cameras_is_calibrated_unlike(tmp_path) -> None:
    """A user trial put another camera's calibration of the same image size in survey.yaml:
    accepted frame by frame, 0.6 % of the directions trusted falsely."""
    from types import SimpleNamespace

    from predisat.camera.models import CameraModel
    from predisat.reconstruct.batch import camera_pair_warnings

    fish = CameraModel.fisheye_from_fov(640, 480, 180.0)
    pin = CameraModel.pinhole_from_fov(640, 480, 74.0)

    def survey(left, right):
        return SimpleNamespace(cameras={"left": SimpleNamespace(camera=left),
                                        "right": SimpleNamespace(camera=right)})  # fmt: skip

    assert camera_pair_warnings(survey(fish, fish)) == []
    (line,) = camera_pair_warnings(survey(fish, pin))
    assert "left and right cameras' calibrations differ" in line and "pinhole" in line
    wider = CameraModel.fisheye_from_fov(640, 480, 150.0)  # same model, 20 % longer focal
    assert len(camera_pair_warnings(survey(fish, wider))) == 1


def test_a_stopped_rerun_withdraws_the_previous_masks(
    survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A user trial: a corrected survey's rerun, stopped after its first chunk, left the wrong
    run's masks and record in the folder, read with exit 0 (0.34 % false trust). A rerun that
    is not the published run withdraws them before any work; the same run's rerun keeps
    them."""
    from predisat.masks.fileformat import MaskFileError

    # the rerun publishes again: its created_utc, pinned, lest two runs a second apart differ
    # (a CI run under load failed on the timestamp's last digit)
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    out = tmp_path / "masks"
    process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky)
    before = (out / "masks.parquet").read_bytes()
    process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky)
    assert (out / "masks.parquet").read_bytes() == before  # its own rerun: still published
    other = PipelineParams(chunk_m=30.0, segmenter="blue", mount_doubt_deg=1.0)
    with pytest.raises(RunStopped):
        process_survey(survey_dir, out, other, progress=False, segmenter=blue_sky,
                       max_chunks=1)  # fmt: skip
    assert not (out / "masks.parquet").exists() and not (out / "provenance.json").exists()
    with pytest.raises(MaskFileError, match=r"without masks\.parquet"):
        read_masks(out)


def test_a_track_changed_under_the_same_name_redoes_the_chunks(
    survey_dir: Path, tmp_path: Path
) -> None:
    """A user trial: a corrected track map with the same name resumed every chunk of the run
    on the wrong one (the run key held the map's name only)."""
    from predisat.track.map import TrackMap, demo_track

    out = tmp_path / "masks"
    t = demo_track()
    process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky, track=t)
    lat, lon, h = t.position_at(np.arange(0.0, t.length_m, 5.0))
    moved = TrackMap.from_latlon(lat + 0.5 / 111_200.0, lon, h, name=t.name)
    res = process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky,
                         track=moved)  # fmt: skip
    assert (res.chunks_done, res.chunks_skipped) == (3, 0)
    again = process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky,
                           track=moved)  # fmt: skip
    assert (again.chunks_done, again.chunks_skipped) == (0, 3)


def test_a_chunk_reads_whole_views_and_merges_them_as_the_survey_does(
    survey_dir: Path, tmp_path: Path
) -> None:
    """A review: a chunk's window cut through a crawl, and the chunk merged and sliced the part
    it held otherwise than the whole survey does, so a position's views depended on where the
    chunks fell. A chunk now reads every frame of a view it reads one of, with the survey's
    view of each frame."""
    import dataclasses

    from predisat.reconstruct.batch import _chunk_jobs, _plan
    from predisat.reconstruct.stops import stop_ids
    from predisat.survey import Survey

    survey = Survey.load(survey_dir, check_images=False)
    fr = survey.frames
    overlap = PARAMS.reconstruction.overlap_m
    # the left camera crawls 0.1 m a frame across the far edge of the first chunk's window
    # (its last position 3020 m plus the overlap)
    left = np.flatnonzero(fr.side == "left")
    ch = np.asarray(fr.chainage_m, float).copy()
    ch[left] = 3020.0 + overlap - 0.3 + 0.1 * np.arange(left.size)
    ch = np.round(ch, 3)
    survey = dataclasses.replace(survey, frames=dataclasses.replace(fr, chainage_m=ch))
    plan = _plan(survey, survey.track, PARAMS, tmp_path / "o", ch, {})
    view = stop_ids(fr.side, ch, PARAMS.stop_gap_m, PARAMS.stop_span_m)
    cut = False
    for name, *_, s in plan.chunks:
        window = np.flatnonzero((ch >= s.min() - overlap) & (ch <= s.max() + overlap))
        idx = plan.frames_of[name]
        assert set(window.tolist()) <= set(idx.tolist()), name
        for v in np.unique(view[idx]):
            whole = np.flatnonzero(view == v)
            assert set(whole.tolist()) <= set(idx.tolist()), name  # whole views
            cut |= not set(whole.tolist()) <= set(window.tolist())
    assert cut  # some window alone would have cut a view: the check above meant something
    att = plan.provenance["attitude"]
    for job in _chunk_jobs(plan, list(plan.chunks), {}, None):
        # and the survey's attitude verdicts, the same in every chunk
        assert job.attitude_verdicts == (att["imu_distrusted"], att["cant_table_distrusted"])
        by_id = {f.frame_id: f.view_id for f in job.frames}
        for i in plan.frames_of[job.name]:
            assert by_id[str(fr.frame_id[i])] == int(view[i])


def test_a_segmenter_that_fails_is_tried_again_by_the_next_run(tmp_path: Path) -> None:
    """A failure of the run (a worker's threads sharing one network, memory), not of the
    image, was cached and set the frame aside in every later run "as in a run before" (a user
    trial); an image that cannot be segmented for what it is (its size) stays cached."""
    import cv2

    from predisat.reconstruct.framecache import FrameJob, read_cache
    from predisat.reconstruct.frames import segment_frame

    image = tmp_path / "f.png"
    grey = np.linspace(40, 220, 37 * 5).reshape(5, 37).astype(np.uint8)  # not a blank frame
    cv2.imwrite(str(image), np.dstack([grey] * 3))
    job = FrameJob("f", str(image), 37, 5, str(tmp_path / "f.npz"))

    def failing(img):
        raise cv2.error("OpenCV(4.x) error: (-215:Assertion failed) buf.shape() == m.shape()\n")

    fid, problem = segment_frame(job, failing)
    assert fid == "f" and problem is not None and "\n" not in problem
    assert "segmentation failed (error: OpenCV(4.x) error" in problem
    assert read_cache(job) is None  # the next run tries again

    def working(img):
        return np.zeros(img.shape[:2], bool), np.ones(img.shape[1], np.float32)

    assert segment_frame(job, working) == ("f", None)
    assert isinstance(read_cache(job), tuple)
    wrong = FrameJob("f", str(image), 40, 5, str(tmp_path / "g.npz"))  # the image's size
    _, problem = segment_frame(wrong, working)
    assert problem is not None and "calibration says 40x5" in problem
    assert read_cache(wrong) is not None  # a verdict on the image: kept


def test_a_wrong_address_is_refused_before_the_finished_run_is_withdrawn(
    survey_dir: Path, first_run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A user trial reran a finished folder on a port where nothing listens: refused, but only
    after its masks.parquet, provenance.json and bad_frames.csv had been deleted."""
    import socket

    import predisat.scheduler as sched
    from predisat.scheduler import Scheduler

    monkeypatch.setattr(sched, "CONNECT_TIMEOUT_S", 1.0)
    out = tmp_path / "masks"
    shutil.copytree(first_run[0], out)
    before = sorted(p.name for p in out.iterdir())
    assert "masks.parquet" in before and "provenance.json" in before
    with socket.socket() as s:  # a free port: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    other = replace(PARAMS, thin_deg=0.5)  # another run key: the finished files would go
    with pytest.raises(OSError, match=f"127.0.0.1:{port}"):
        process_survey(survey_dir.resolve(), out, other, progress=False,
                       scheduler=Scheduler.at(f"tcp://127.0.0.1:{port}"))  # fmt: skip
    assert sorted(p.name for p in out.iterdir()) == before


def test_a_rerun_with_other_settings_says_it_withdrew_the_finished_run(
    first_run, survey_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A user trial reran a finished folder with another --thin-deg and saw only "(0 already
    done)": nothing said its masks had been withdrawn and its chunks would be redone."""
    out0, _ = first_run
    out = tmp_path / "copy"
    shutil.copytree(out0, out)
    capsys.readouterr()
    process_survey(survey_dir, out, PARAMS, progress=False, segmenter=blue_sky)
    assert "withdrawn" not in capsys.readouterr().err  # its own run's masks: kept
    other = replace(PARAMS, chunk_m=60.0)
    process_survey(survey_dir, out, other, progress=False, segmenter=blue_sky)
    err = capsys.readouterr().err
    assert f"note: {out} held the masks of a finished run with other settings" in err
    assert (out / "masks.parquet").is_file()  # and the new run published its own


def test_a_frame_whose_segmentation_raised_is_segmented_again_by_the_next_run(
    survey_dir: Path, tmp_path: Path
) -> None:
    """Not caching the failure is not enough: the chunk that set the frame aside finished, and
    the next run kept it, and the frame "as in a run before" (a run on a worker whose threads
    shared one network finished with 20 such frames)."""
    p = PipelineParams(chunk_m=30.0, segmenter="blue")
    calls: list[int] = []

    def flaky(image: np.ndarray) -> tuple[np.ndarray, None]:
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("two threads fed one network")
        return blue_sky(image)

    out = tmp_path / "masks"
    first = process_survey(survey_dir, out, p, progress=False, segmenter=flaky)
    assert len(first.bad_frames) == 1
    again = process_survey(survey_dir, out, p, progress=False, segmenter=blue_sky)
    assert again.bad_frames == ()
    assert process_survey(survey_dir, out, p, progress=False, segmenter=blue_sky).bad_frames == ()


@pytest.fixture(scope="module")
def canted_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A finished run of a small fisheye survey on the demo's canted curve (roll 5-8 deg,
    measured in the manifest), in 3 chunks."""
    from predisat.camera.models import default_camera
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    base = tmp_path_factory.mktemp("canted")
    cam = default_camera("fisheye").resized(160, 120)
    generate_survey(demo_track(), 760.0, 820.0, sky="clear", seed=4, out_dir=base, camera=cam,
                    progress=False, cant_speed_kmh=100.0)  # fmt: skip
    process_survey(base / "survey", base / "out", PARAMS, progress=False, scheduler="serial")
    return base / "survey", base / "out"


def test_finished_chunk_jobs_rebuild_the_frames_the_run_reconstructed(canted_run) -> None:
    """A diagnosis reconstructs the published masks bit for bit from the rebuilt chunks (the
    vehicle's attitude included: the level frames' masks differ on this canted curve)."""
    from predisat.reconstruct.attitude import level_attitudes
    from predisat.reconstruct.batch import finished_chunk_jobs
    from predisat.reconstruct.carving import Reconstructor
    from predisat.reconstruct.chunks import chunk_inputs

    survey, out = canted_run
    written = read_masks(out / "masks.parquet", close_holes=False)
    jobs = finished_chunk_jobs(out, survey, lo_m=785.0, hi_m=815.0)
    assert [j.name for j in jobs] == ["780_810", "810_840"]
    for job in jobs:
        inputs = chunk_inputs(job)
        rec = Reconstructor(inputs.params).run(
            list(inputs.views), inputs.positions_m, inputs.track,
            side_cameras=list(inputs.side_cameras),
        )  # fmt: skip
        at = np.searchsorted(written.chainage_m, inputs.positions_m)
        np.testing.assert_array_equal(written.chainage_m[at], inputs.positions_m)
        assert np.array_equal(rec.mask_el_deg, written.mask_el_deg[at])
        assert np.array_equal(rec.to_maskset(inputs.track).source, written.source[at])
    # the same chunk's frames without the vehicle's attitude (as scripts rebuilt them before)
    monkey = pytest.MonkeyPatch()
    import predisat.reconstruct.chunks as chunks

    monkey.setattr(chunks, "frame_attitudes", level_attitudes)
    try:
        level = chunk_inputs(jobs[0])
    finally:
        monkey.undo()
    rec = Reconstructor(level.params).run(list(level.views), level.positions_m, level.track,
                                          side_cameras=list(level.side_cameras))  # fmt: skip
    at = np.searchsorted(written.chainage_m, level.positions_m)
    assert np.abs(rec.mask_el_deg - written.mask_el_deg[at]).max() > 1.0


def test_finished_chunk_jobs_refuse_other_parameters_than_the_run(canted_run) -> None:
    from predisat.reconstruct.batch import finished_chunk_jobs

    survey, out = canted_run
    with pytest.raises(ValueError, match=r"params\.chunk_m .*pass params="):
        finished_chunk_jobs(out, survey, params=PipelineParams(chunk_m=50.0))
    with pytest.raises(ValueError, match="finished predisat process run"):
        finished_chunk_jobs(out / "chunks", survey)


def test_finished_chunk_jobs_take_each_chunks_own_set_aside_frames(canted_run, tmp_path) -> None:
    """A frame one chunk set aside (its cache did not read there) was read by its neighbour:
    each rebuilt chunk takes its own marker's list, not the run's (m9)."""
    import json
    import shutil

    from predisat.reconstruct.batch import finished_chunk_jobs

    survey, out = canted_run
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    jobs = finished_chunk_jobs(copy, survey, lo_m=785.0, hi_m=815.0)
    first, second = jobs[0].name, jobs[1].name
    shared = sorted({f.frame_id for f in jobs[0].frames} & {f.frame_id for f in jobs[1].frames})
    assert shared
    marker = copy / "chunks" / f"{first}.json"
    done = json.loads(marker.read_text())
    done["bad_frames"] = [*done.get("bad_frames", []), {
        "frame_id": shared[0], "message": "cache did not read", "stage": "segment"}]
    marker.write_text(json.dumps(done))
    again = {j.name: j for j in finished_chunk_jobs(copy, survey, lo_m=785.0, hi_m=815.0)}
    assert shared[0] in {b.frame_id for b in again[first].known_bad}
    assert shared[0] not in {b.frame_id for b in again[second].known_bad}
