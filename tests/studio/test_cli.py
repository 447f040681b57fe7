"""``biomorph studio`` prints its URL, binds loopback by default and stops on Ctrl-C."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
import urllib.request

from biomorph.studio.server import free_port


def test_studio_command_serves_and_stops_cleanly(tmp_path):
    port = free_port()
    cmd = [
        sys.executable,
        "-c",
        "from biomorph.cli import main; main()",
        "studio",
        "--port",
        str(port),
        "--data",
        str(tmp_path),
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = None
        end = time.monotonic() + 60
        while time.monotonic() < end and url is None:
            line = proc.stdout.readline()
            if "open http" in line:
                url = line.split("open ", 1)[1].split()[0]
            elif proc.poll() is not None:
                break
        assert url == f"http://127.0.0.1:{port}", (url, proc.stderr.read())
        with urllib.request.urlopen(url, timeout=10) as resp:
            assert resp.status == 200
            assert b"<html" in resp.read().lower()
        # loopback only: the port is not reachable on another local address of the host
        import socket

        addrs = {
            a[4][0] for a in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)
        } - {"127.0.0.1"}
        for addr in list(addrs)[:1]:
            with socket.socket() as s:
                s.settimeout(2)
                assert s.connect_ex((addr, port)) != 0, f"studio reachable on {addr}"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "stopping the studio" in out
        assert "Traceback" not in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_bad_port_is_one_clear_error(tmp_path, capsys):
    from biomorph.cli import run

    assert run(["studio", "--port", "70000", "--data", str(tmp_path)]) == 2
    assert "--port" in capsys.readouterr().err
