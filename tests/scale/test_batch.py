"""run_batch: serial == distributed, per-item failures, resume, Ctrl-C, report."""

from __future__ import annotations

import _thread
import json
import logging
import multiprocessing
import threading
import time

import pytest

from biomorph.errors import ParameterError
from biomorph.scale import BatchReport, run_batch
from tests.scale import die_on_two, fail_on_three, slow, square_stats

distributed = pytest.importorskip("dask.distributed")


@pytest.fixture(scope="module")
def scheduler():
    """One 2-process cluster shared by the tests that pass an address. A task whose worker
    dies is not retried elsewhere (allowed-failures 0), so a crash is reported at once."""
    import dask

    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        cluster = distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        )
    yield cluster.scheduler_address
    cluster.close()


def test_local_cluster_matches_serial():
    seeds = list(range(10))
    serial = run_batch(seeds, square_stats, workers=0, progress=False)
    par = run_batch(seeds, square_stats, workers=2, progress=False)
    assert serial.scheduler == "serial" and serial.workers == 0
    assert par.scheduler == "local" and par.workers == 2
    assert par.results == serial.results  # exact floats, same order
    assert list(par.results) == [str(s) for s in seeds]
    assert par.ok == serial.ok == [str(s) for s in seeds]
    assert par.failed == [] and set(par.item_seconds) == set(par.ok)


def test_failing_item_is_reported_and_others_finish(scheduler):
    for kwargs in ({"workers": 0}, {"scheduler": scheduler}):
        rep = run_batch(range(6), fail_on_three, key=lambda s: f"seed{s}", progress=False, **kwargs)
        assert rep.failed == [("seed3", "ValueError: item 3 is cursed")]
        assert rep.ok == ["seed0", "seed1", "seed2", "seed4", "seed5"]
        assert rep.results == {"seed0": 0, "seed1": 1, "seed2": 4, "seed4": 16, "seed5": 25}
        assert "cursed" in rep.tracebacks["seed3"] and "fail_on_three" in rep.tracebacks["seed3"]
        assert rep.exit_code == 1
        assert rep.summary().startswith("batch: 5 ok, 1 failed, 0 skipped")


def test_rerun_skips_done_items_with_markers(tmp_path, scheduler):
    first = run_batch(
        range(6),
        fail_on_three,
        out_dir=tmp_path,
        scheduler=scheduler,
        progress=False,
        description="seeds",
    )
    assert first.skipped == [] and len(first.ok) == 5
    saved = json.loads((tmp_path / "batch_report.json").read_text())
    assert saved["n_ok"] == 5 and saved["failed"][0]["key"] == "3"
    assert saved["description"] == "seeds"
    # second run: only the failed item is tried again (serially: one item left)
    second = run_batch(range(6), square_stats, out_dir=tmp_path, progress=False)
    assert second.skipped == ["0", "1", "2", "4", "5"]
    assert second.ok == ["3"] and second.scheduler == "serial"
    third = run_batch(range(6), square_stats, out_dir=tmp_path, scheduler=scheduler, progress=False)
    assert len(third.skipped) == 6 and third.ok == []


def test_done_callable_decides_what_to_skip():
    rep = run_batch(range(5), square_stats, done=lambda s: s % 2 == 0, workers=0, progress=False)
    assert rep.skipped == ["0", "2", "4"] and rep.ok == ["1", "3"]
    assert rep.to_dict()["n_skipped"] == 3


def test_report_to_dict_is_json():
    rep = run_batch(range(4), fail_on_three, workers=0, progress=False)
    d = json.loads(json.dumps(rep.to_dict()))
    assert d["total"] == 4 and d["n_ok"] == 3 and d["n_failed"] == 1
    assert d["failed"][0]["error"] == "ValueError: item 3 is cursed"
    assert set(d["item_seconds"]) == {"0", "1", "2", "3"}
    assert isinstance(BatchReport().to_dict()["mean_item_seconds"], float)


def test_bad_parameters():
    with pytest.raises(ParameterError, match="unique"):
        run_batch([1, 2, 3], square_stats, key=lambda s: "same", workers=0)
    with pytest.raises(ParameterError, match="workers"):
        run_batch([1, 2], square_stats, workers=-1)
    empty = run_batch([], square_stats)
    assert empty.total == 0 and empty.failed == []


def _no_new_children(before: set, timeout: float = 15.0) -> bool:
    deadline = time.monotonic() + timeout
    while set(multiprocessing.active_children()) - before and time.monotonic() < deadline:
        time.sleep(0.2)
    return not set(multiprocessing.active_children()) - before


def test_ctrl_c_while_running_cancels_and_shuts_down(monkeypatch):
    from biomorph.scale import batch

    real = batch._run_distributed

    fired: list[float] = []

    def ctrl_c() -> None:
        fired.append(time.perf_counter())
        _thread.interrupt_main()

    def interrupted_soon(*args, **kwargs):  # Ctrl-C one second into the work
        threading.Timer(1.0, ctrl_c).start()
        return real(*args, **kwargs)

    monkeypatch.setattr(batch, "_run_distributed", interrupted_soon)
    before = set(multiprocessing.active_children())  # e.g. the module's shared cluster
    with pytest.raises(KeyboardInterrupt):
        run_batch(range(60), slow, workers=2, progress=False)  # 15 s of work
    # the remaining ~14 s of work were cancelled, not waited for
    assert time.perf_counter() - fired[0] < 10
    assert _no_new_children(before)


def test_ctrl_c_during_cluster_start_leaves_no_workers(monkeypatch):
    class InterruptedCluster(distributed.LocalCluster):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            # Ctrl-C after the workers were spawned but before the constructor returned:
            # unless it is held, nobody holds a reference to close the cluster
            _thread.interrupt_main()

    monkeypatch.setattr(distributed, "LocalCluster", InterruptedCluster)
    before = set(multiprocessing.active_children())
    with pytest.raises(KeyboardInterrupt):
        run_batch(range(4), slow, workers=2, progress=False)
    assert _no_new_children(before)


def test_a_held_ctrl_c_is_handed_to_the_handler_installed_before():
    """A Ctrl-C deferred while the cluster starts reaches the handler that was there
    before (the CLI's interrupt guard), which then raises: without it the CLI ended with
    exit 130 but never printed its one-line message."""
    import os
    import signal

    from biomorph.scale.batch import _held_interrupt

    seen: list[int] = []

    def guard(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, guard)
    try:
        with pytest.raises(KeyboardInterrupt):
            with _held_interrupt() as interrupted:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.05)  # delivered to the holding handler, not raised here
                assert interrupted() and seen == []
        assert seen == [signal.SIGINT]
        with _held_interrupt() as interrupted:  # no Ctrl-C: nothing handed on
            pass
        assert not interrupted() and seen == [signal.SIGINT]
    finally:
        signal.signal(signal.SIGINT, previous)


WORKER_SIGNALS_PROBE = """
import os
from biomorph.scale.batch import _client
if __name__ == "__main__":
    with _client(2, None) as client:
        for pid in client.run(os.getpid).values():
            status = open(f"/proc/{pid}/status").read().splitlines()
            print(int(next(l for l in status if l.startswith("SigIgn")).split()[1], 16) & 2)
    import multiprocessing.spawn as s
    print(os.fsdecode(s.get_executable()))
"""


@pytest.mark.skipif(not __import__("os").path.exists("/proc/self/status"), reason="needs /proc")
def test_local_cluster_workers_start_with_ctrl_c_ignored(tmp_path):
    """The workers are spawned with SIGINT ignored (a Ctrl-C to the process group while
    one is still importing must not print its traceback); the parent handles Ctrl-C and
    closes them. Spawning afterwards uses the interpreter itself again."""
    import subprocess
    import sys

    script = tmp_path / "probe.py"
    script.write_text(WORKER_SIGNALS_PROBE)
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120, check=True
    ).stdout.split()
    assert out[:2] == ["2", "2"], out
    assert out[2] == sys.executable


def test_the_worker_wrapper_is_skipped_where_it_cannot_run(monkeypatch):
    """A temporary folder mounted noexec cannot run the wrapper: the spawn keeps the
    interpreter itself (and the folder is removed either way)."""
    import multiprocessing.spawn as mp_spawn
    import os
    import subprocess

    from biomorph.scale.batch import _workers_ignore_sigint

    exe = mp_spawn.get_executable()
    made: list[str] = []
    real_mkdtemp = __import__("tempfile").mkdtemp

    def mkdtemp(*a, **k):
        made.append(real_mkdtemp(*a, **k))
        return made[-1]

    def noexec(*a, **k):
        raise PermissionError(13, "Permission denied", a[0][0])

    monkeypatch.setattr("tempfile.mkdtemp", mkdtemp)
    monkeypatch.setattr(subprocess, "run", noexec)
    with _workers_ignore_sigint():
        assert mp_spawn.get_executable() == exe
    assert mp_spawn.get_executable() == exe and made and not os.path.exists(made[0])
    monkeypatch.undo()
    with _workers_ignore_sigint():  # where it runs, the spawn goes through it
        assert os.fsdecode(mp_spawn.get_executable()).endswith("/python")
        assert mp_spawn.get_executable() != exe
    assert mp_spawn.get_executable() == exe


def test_dead_worker_fails_its_item_only(scheduler):
    rep = run_batch(range(6), die_on_two, scheduler=scheduler, progress=False)
    failed = dict(rep.failed)
    assert "worker process died" in failed["2"]
    assert set(rep.ok) | set(failed) == {str(i) for i in range(6)}
    # with zero allowed failures a task queued on the dying worker may go down with it;
    # everything that finished is right
    assert all(rep.results[k] == int(k) for k in rep.ok) and len(rep.ok) >= 3


LOOPBACK_PROBE = """
import psutil
from biomorph.scale.batch import _client
if __name__ == "__main__":
    with _client(2, None) as client:
        print(client.scheduler_info()["address"])
        procs = [psutil.Process(), *psutil.Process().children(recursive=True)]
        for p in procs:
            for c in p.net_connections(kind="inet"):
                if c.status == psutil.CONN_LISTEN:
                    print(c.laddr.ip)
"""


def test_local_cluster_listens_on_loopback_only(tmp_path):
    """Scheduler, nannies, workers and dashboards of a LocalCluster bind 127.0.0.1 (probed
    in a fresh process, so no other cluster's sockets are counted)."""
    import subprocess
    import sys

    script = tmp_path / "probe.py"
    script.write_text(LOOPBACK_PROBE)
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120, check=True
    ).stdout.split()
    assert out[0].startswith("tcp://127.0.0.1:")
    assert len(out[1:]) >= 4  # scheduler + dashboard + two workers at least
    assert set(out[1:]) == {"127.0.0.1"}, out


def test_markers_keyed_by_item_and_options(tmp_path):
    first = run_batch(
        range(3),
        square_stats,
        out_dir=tmp_path,
        workers=0,
        progress=False,
        options={"format": "glb"},
    )
    assert first.ok == ["0", "1", "2"]
    same = run_batch(
        range(3),
        square_stats,
        out_dir=tmp_path,
        workers=0,
        progress=False,
        options={"format": "glb"},
    )
    assert same.skipped == ["0", "1", "2"]
    other = run_batch(
        range(3),
        square_stats,
        out_dir=tmp_path,
        workers=0,
        progress=False,
        options={"format": "bvh"},
    )
    assert other.ok == ["0", "1", "2"] and other.skipped == []
    # an empty (half-written, legacy) marker never counts as done
    marker = tmp_path / ".batch_done" / "1"
    marker.write_text("")
    again = run_batch(
        range(3),
        square_stats,
        out_dir=tmp_path,
        workers=0,
        progress=False,
        options={"format": "bvh"},
    )
    assert again.ok == ["1"]


KILL_SCRIPT = """
import sys
from biomorph.scale import run_batch
from tests.scale import staged_outputs
out = sys.argv[1]
run_batch([(out, i) for i in range(4)], staged_outputs, out_dir=out, key=lambda it: str(it[1]),
          workers=0, progress=False)
"""


def _snapshot(folder):
    """Every file's bytes (markers: existence only, their digest includes the folder)."""
    return {
        p.relative_to(folder).as_posix(): b"" if p.parent.name == ".batch_done" else p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != "batch_report.json"
    }


@pytest.mark.parametrize("kill_after", [0.35, 0.75, 1.15, 1.55])
def test_resume_after_sigkill_is_exact(tmp_path, kill_after):
    """SIGKILL a serial batch at several points (between and inside items, between the two
    files of one item); the re-run finishes exactly what is missing: the same files as an
    uninterrupted run, no temporary files, no item done twice."""
    import os
    import signal
    import subprocess
    import sys

    ref, out = tmp_path / "ref", tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    subprocess.run([sys.executable, "-c", KILL_SCRIPT, str(ref)], check=True, env=env, timeout=60)
    proc = subprocess.Popen([sys.executable, "-c", KILL_SCRIPT, str(out)], env=env)
    t0 = time.monotonic()
    while not (out / "0.first").exists() and time.monotonic() - t0 < 30:
        time.sleep(0.005)
    time.sleep(kill_after)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    subprocess.run([sys.executable, "-c", KILL_SCRIPT, str(out)], check=True, env=env, timeout=60)
    assert _snapshot(out) == _snapshot(ref)
    assert [p for p in out.rglob("*") if ".tmp-" in p.name or p.name == ".biomorph.lock"] == []


def test_tree_batch_redoes_an_item_killed_before_its_last_file(tmp_path):
    """An item killed after summary.json but before preview.png has no completion marker:
    the re-run redoes it (it used to count as done once summary.json existed)."""
    from biomorph.cli import run
    from biomorph.io import write_points
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    cloud = write_points(
        tmp_path / "birch.ply", simulate_scan(generate_tree("birch", seed=3), n_points=1500, seed=3)
    )
    out = tmp_path / "out"
    assert run(["tree", "batch", str(cloud), "--workers", "0", "--out", str(out)]) == 0
    item = out / "birch"
    assert (item / "summary.json").exists() and (item / "preview.png").exists()
    (item / "preview.png").unlink()  # the state a SIGKILL between the two files leaves
    (out / ".batch_done" / "birch").unlink()
    assert run(["tree", "batch", str(cloud), "--workers", "0", "--out", str(out)]) == 0
    assert (item / "preview.png").exists()


def test_creature_batch_resume_is_keyed_by_format(tmp_path, capsys):
    from biomorph.cli import run

    out = tmp_path / "c"
    base = [
        "creature",
        "batch",
        "--count",
        "2",
        "--chunk",
        "1",
        "--workers",
        "0",
        "--out",
        str(out),
    ]
    assert run([*base, "--format", "json"]) == 0
    assert sorted(p.suffix for p in out.glob("creature_*")) == [".json", ".json"]
    assert run([*base, "--format", "bvh"]) == 0  # used to write nothing and exit 0
    assert sorted(p.suffix for p in out.glob("creature_*")) == [".bvh", ".bvh", ".json", ".json"]
    assert run([*base, "--format", "bvh"]) == 0
    assert "0 failed" in capsys.readouterr().out


@pytest.mark.parametrize("address", ["bogus", "tcp://", "tcp://host"])
def test_malformed_address_is_refused_before_any_client(address, monkeypatch):
    """No Client is made for an address without a port: a Client failing in __init__
    closes itself in __del__, and when the garbage collector ran that inside the next
    Client's loop start-up it waited for the lock that start-up held (the test below hung
    the suite)."""
    from biomorph.errors import BiomorphError

    def no_client(*a, **k):
        raise AssertionError("a Client was made for a malformed address")

    monkeypatch.setattr(distributed, "Client", no_client)
    with pytest.raises(BiomorphError, match="missing port"):
        run_batch(range(3), square_stats, scheduler=address, progress=False)


@pytest.mark.parametrize("address", ["bogus", "tcp://"])
def test_malformed_scheduler_address_is_one_error(address):
    from biomorph.errors import BiomorphError

    with pytest.raises(BiomorphError, match="expected an address like tcp://host:8786"):
        run_batch(range(3), square_stats, scheduler=address, progress=False)
