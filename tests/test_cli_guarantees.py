"""The CLI's cross-cutting guarantees (issue 18): Ctrl-C, non-regular inputs, outputs that are
inputs, locked output folders and appended files, error messages naming the real target.

Ctrl-C is tested through a real process (``python -m biomorph.cli``) receiving SIGINT on its
whole process group, as a terminal sends it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from biomorph._cli import INTERRUPT_LINE, LOCK_NAME, folder_lock
from biomorph.cli import run

CLI = [sys.executable, "-m", "biomorph.cli"]


def _maps_numpy(pid: int) -> bool:
    """True once the process has mapped numpy's C core: ``biomorph.cli`` has installed its
    start-up Ctrl-C handler (the ``biomorph`` package itself imports nothing heavy) and is
    inside its imports. Before that the interpreter is still starting (``site``), where
    Python's own default applies."""
    try:
        return "_multiarray_umath" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def _interrupt(
    args: list[str], wait_for: Path | Callable[[int], bool] | None, delay: float
) -> tuple[int, str, float]:
    """Start the CLI, wait until ``wait_for`` exists (the command body has begun) or, a
    predicate of the process id, holds, plus ``delay`` s; send SIGINT to its process group;
    return (exit code, stderr, seconds to stop). Waiting on an event instead of a fixed
    time keeps the test meaningful on a loaded machine."""
    proc = subprocess.Popen(
        CLI + args,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    t0 = time.monotonic()

    def started() -> bool:
        if wait_for is None:
            return True
        if callable(wait_for):
            return wait_for(proc.pid)
        return wait_for.exists()

    while not started() and proc.poll() is None and time.monotonic() - t0 < 90:
        time.sleep(0.002)
    assert proc.poll() is None, proc.communicate()
    time.sleep(delay)
    os.killpg(proc.pid, signal.SIGINT)
    t1 = time.monotonic()
    _, err = proc.communicate(timeout=30)
    return proc.returncode, err, time.monotonic() - t1


def _one_interrupt_line(err: str) -> None:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert lines == [INTERRUPT_LINE], err
    assert "Traceback" not in err


def _temp_files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".tmp-" in p.name or p.name == LOCK_NAME]


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs Linux /proc")
def test_ctrl_c_during_imports_one_line_exit_130(tmp_path):
    code, err, took = _interrupt(["tree", "synth", "--out", str(tmp_path / "o")], _maps_numpy, 0.0)
    assert code == 130
    _one_interrupt_line(err)
    assert took < 1.0
    assert not (tmp_path / "o").exists()


def test_ctrl_c_during_work_one_line_exit_130_no_partial_files(tmp_path):
    out = tmp_path / "o"
    code, err, took = _interrupt(
        ["tree", "synth", "--points", "3000000", "--out", str(out)], out / LOCK_NAME, 0.3
    )
    assert code == 130
    _one_interrupt_line(err)
    assert took < 1.0
    assert _temp_files(out) == []


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    from biomorph.io import write_points
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    d = tmp_path_factory.mktemp("clouds")
    cloud = simulate_scan(generate_tree("birch", seed=1), n_points=1500, seed=1)
    return [write_points(d / f"{name}.ply", cloud) for name in ("a", "b", "c")]


def test_ctrl_c_during_batch_worker_start_one_line(tmp_path, clouds):
    out = tmp_path / "batch"
    code, err, took = _interrupt(
        ["tree", "batch", *map(str, clouds), "--workers", "2", "--out", str(out)],
        out / LOCK_NAME,
        0.5,
    )
    assert code == 130
    _one_interrupt_line(err)  # no worker tracebacks, no misleading multiprocessing error
    assert took < 1.5  # the process group is gone (workers killed with the parent)


def test_named_pipe_and_device_refused_not_read(tmp_path, capsys):
    fifo = tmp_path / "cloud.xyz"
    os.mkfifo(fifo)
    for argv in (
        ["info", str(fifo)],
        ["tree", "skeletonize", str(fifo), "--out", str(tmp_path / "o")],
        ["info", "/dev/zero"],
    ):
        assert run(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err
        assert "named pipe" in err or "device file" in err
    assert not (tmp_path / "o").exists()


def test_output_that_is_an_input_is_refused(tmp_path, capsys, clouds):
    out = tmp_path / "out"
    out.mkdir()
    own = out / "skeleton.ply"
    own.write_bytes(clouds[0].read_bytes())
    before = own.read_bytes()
    assert run(["tree", "skeletonize", str(own), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "skeleton.ply" in err and "input" in err and len(err.splitlines()) == 1
    assert own.read_bytes() == before
    assert _temp_files(out) == []
    bvh = tmp_path / "m.bvh"
    bvh.write_text("HIERARCHY\n")
    assert run(["motion", "reorient", str(bvh), "-o", str(bvh)]) == 2
    assert "input" in capsys.readouterr().err


def test_second_run_into_a_locked_folder_is_refused(tmp_path, capsys):
    out = tmp_path / "o"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import time; from biomorph._cli import folder_lock\n"
            f"with folder_lock({str(out)!r}):\n"
            "    print('locked', flush=True); time.sleep(30)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert run(["tree", "synth", "--points", "500", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "another biomorph run" in err and str(out) in err
        assert not (out / "cloud.ply").exists()
    finally:
        holder.kill()
        holder.wait()


def test_stale_temp_files_of_a_killed_run_are_removed(tmp_path):
    out = tmp_path / "o"
    (out / "sub").mkdir(parents=True)
    stale = [out / ".cloud.ply.tmp-abcd1234.ply", out / "sub" / ".summary.json.tmp-zz_9y8x7.json"]
    for p in stale:
        p.write_bytes(b"x" * 100)
    keep = out / "notes.tmp-abcd1234.txt"  # not a name atomic_path creates
    keep.write_text("mine")
    with folder_lock(out) as removed:
        assert sorted(removed) == sorted(stale)
    assert not any(p.exists() for p in stale) and keep.exists()
    assert not (out / LOCK_NAME).exists()


def test_concurrent_annotate_loses_no_rows(tmp_path):
    from tests.creature.test_export_cli import SVG

    ds = tmp_path / "species.csv"
    procs = []
    for i in range(3):
        svg = tmp_path / f"animal{i}.svg"
        svg.write_text(SVG)
        procs.append(
            subprocess.Popen(
                CLI
                + ["creature", "annotate", str(svg), "--weight", str(10 + i), "--dataset", str(ds)],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    for p in procs:
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
    from biomorph.creature.dataset import load_species

    names = list(load_species(ds).name)
    assert sorted(names[-3:]) == ["animal0", "animal1", "animal2"]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores file permissions")
def test_permission_error_names_the_target_not_the_temp_file(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert run(["tree", "synth", "--points", "500", "--out", str(ro / "x")]) == 2
    finally:
        ro.chmod(0o755)
    err = capsys.readouterr().err
    assert str(ro) in err and ".tmp-" not in err


def test_os_errors_name_the_target(tmp_path):
    """Disk full / permission denied while writing name the target, never the temp file."""
    import errno

    from biomorph.io.atomic import atomic_path

    target = tmp_path / "out.ply"
    with pytest.raises(OSError) as info:
        with atomic_path(target) as tmp:
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp))
    assert info.value.filename == str(target) and info.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(OSError) as info:
        with atomic_path(blocker / "inside.txt") as tmp:
            tmp.write_text("never")
    assert ".tmp-" not in str(info.value.filename)


def test_disk_full_message_names_the_path(tmp_path, capsys, monkeypatch):
    import errno

    import biomorph.io.atomic as atomic

    real = os.replace

    def full(src, dst):
        raise OSError(errno.ENOSPC, "No space left on device", src)

    monkeypatch.setattr(atomic.os, "replace", full)
    out = tmp_path / "o"
    try:
        assert run(["tree", "synth", "--points", "500", "--out", str(out)]) == 2
    finally:
        monkeypatch.setattr(atomic.os, "replace", real)
    err = capsys.readouterr().err.strip()
    assert "No space left on device" in err and str(out) in err and ".tmp-" not in err
    assert len(err.splitlines()) == 1
    assert [p for p in out.rglob("*") if ".tmp-" in p.name] == []


def test_warnings_never_precede_the_error_line(tmp_path, capsys, monkeypatch):
    import warnings

    import biomorph.inspect
    from biomorph.errors import FormatError

    def noisy(path):
        warnings.warn("invalid value encountered in divide", RuntimeWarning, stacklevel=1)
        raise FormatError(path, "bad face index 0", line=4)

    monkeypatch.setattr(biomorph.inspect, "describe", noisy)
    assert run(["info", str(tmp_path / "m.obj")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {tmp_path / 'm.obj'}:4: bad face index 0"]


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["tree", "synth", "--points", "2000000000", "--out", "{tmp}/o"], "--points 2000000000"),
        (["leaf", "mesh", "--triangles", "2147483647", "-o", "{tmp}/l.obj"], "--triangles"),
    ],
)
def test_sizes_refused_up_front_with_the_estimate(tmp_path, capsys, argv, needle):
    assert run([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and "of memory" in err and "available" in err
    assert len(err.splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_memory_guard_arithmetic():
    from biomorph.errors import ParameterError, require_memory

    require_memory("small", 1e6, available=10**9)
    with pytest.raises(ParameterError, match=r"needs about 900 MB of memory; 1 GB available"):
        require_memory("big", 9e8, available=10**9)
    with pytest.raises(ParameterError):
        require_memory("nan", float("nan"), available=10**9)


def test_corrupt_laz_through_the_executable_is_one_line(tmp_path):
    from biomorph.io import write_points
    from tests.io.test_las import LAZ_DAMAGE, cloud_with_extras

    good = write_points(tmp_path / "g.laz", cloud_with_extras(500))
    bad = tmp_path / "bad.laz"
    bad.write_bytes(LAZ_DAMAGE["chunk-count"][0](good.read_bytes()))
    res = subprocess.run(CLI + ["info", str(bad)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "chunk" in lines[0] and str(bad) in lines[0]


def test_an_error_raised_by_the_interruption_is_the_interruption(monkeypatch, capsys):
    """Ctrl-C inside an import leaves a half-initialised module whose next import fails:
    that error is the interruption (one line, 130), not an internal error (exit 1) — the
    race seen once under load in `test_ctrl_c_during_imports_one_line_exit_130`."""
    import biomorph.cli as cli

    class Cut:
        def main(self, **_):
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.5)
            except KeyboardInterrupt:
                raise ImportError("cannot import name 'x' (partially initialized module)") from None

    monkeypatch.setattr(cli, "_command", lambda group: Cut())
    assert run(["tree", "synth"]) == 130
    assert INTERRUPT_LINE in capsys.readouterr().err

    class Bug:
        def main(self, **_):
            raise ImportError("a real bug")

    monkeypatch.setattr(cli, "_command", lambda group: Bug())
    assert run(["tree", "synth"]) == 1
