"""Fuzz every reader (all formats, incl. SVG annotations, QSM CSV, .can and the glTF
summary) with mutated and truncated bytes of valid and real files.

A reader may accept a mutated file (many mutations keep it valid) or raise a
:class:`BiomorphError`; any other exception (a library's ValueError, IndexError, a laspy or
plyfile error, UnicodeDecodeError …) is a bug. Each case runs in a child process with a
time limit, so a native abort (a decompressor's panic, a segfault), an allocation that
kills the process, or a hang counts as a failure too. Iterations are bounded (seeded);
``BIOMORPH_FUZZ_ITERATIONS=400`` runs a longer campaign. Readers of modules that do not
exist yet are skipped.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.core.mesh import Mesh
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import BiomorphError
from tests.conftest import SHARED_DATA

ITERATIONS = int(os.environ.get("BIOMORPH_FUZZ_ITERATIONS", "40"))
#: seconds one case may take in its child process before it counts as a hang
CASE_SECONDS = 60 + ITERATIONS

BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0.0 0.0 0.0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0.0 5.2 0.0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0.0 4.0 0.0
    }
  }
  JOINT LeftLeg
  {
    OFFSET 1.0 -1.0 0.0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0.0 -4.0 0.0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.033333
0.0 1.0 2.0 10.0 20.0 30.0 1.0 2.0 3.0 -4.0 5.5e1 6.0
0.1 1.1 2.1 11.0 21.0 31.0 1.5 2.5 3.5 -4.5 5.0 6.5
0.2 1.2 2.2 12.0 22.0 32.0 2.0 3.0 4.0 -5.0 5.0 7.0
"""


def _cloud() -> PointCloud:
    rng = np.random.default_rng(0)
    return PointCloud(
        rng.uniform(0, 3, (40, 3)),
        {
            "intensity": rng.integers(0, 999, 40).astype(np.uint16),
            "Deviation": rng.normal(size=40).astype(np.float32),
        },
    )


def _graph() -> BranchGraph:
    rng = np.random.default_rng(1)
    parent = np.array([-1, 0, 1, 1, 3, 4, 2, -1, 7])
    return BranchGraph(
        rng.normal(size=(9, 3)),
        parent,
        radius=rng.uniform(0.01, 0.1, 9),
        depth=[0, 0, 0, 1, 1, 1, 0, 0, 0],
    )


def _mesh() -> Mesh:
    import trimesh

    m = Mesh.from_any(trimesh.creation.icosphere(1))
    return m.with_(face_ids={"leaf": np.arange(m.n_faces) % 3})


def _module_name(module: str) -> str:
    return module if "." in module else f"biomorph.io.{module}"


def _written(module: str, func: str, ext: str, obj_factory: Callable, **kw) -> Callable:
    def make(tmp: Path) -> bytes:
        mod = importlib.import_module(_module_name(module))
        p = tmp / f"sample{ext}"
        getattr(mod, func)(p, obj_factory(), **kw)
        return p.read_bytes()

    return make


def _text(text: str) -> Callable:
    return lambda tmp: text.encode()


def _shared(*parts: str, limit: int = 60_000) -> Callable:
    def make(tmp: Path) -> bytes:
        p = SHARED_DATA.joinpath(*parts)
        if not p.exists():
            pytest.skip(f"real data {p} absent")
        return p.read_bytes()[:limit] if limit else p.read_bytes()

    return make


def _amc_frames(n_frames: int = 12) -> bytes:
    """The first frames of the shared CMU AMC file (AMC frames start at a line '<k>')."""
    p = SHARED_DATA / "motion" / "cmu_11_01.amc"
    if not p.exists():
        pytest.skip(f"real data {p} absent")
    lines = p.read_text().splitlines()
    cut = next((i for i, ln in enumerate(lines) if ln.strip() == str(n_frames + 1)), len(lines))
    return ("\n".join(lines[:cut]) + "\n").encode()


def _asf_with_amc(tmp: Path) -> bytes:
    (tmp / "fuzz.amc").write_bytes(_amc_frames())
    return _shared("motion", "cmu_11.asf", limit=0)(tmp)


def _amc_with_asf(tmp: Path) -> bytes:
    (tmp / "fuzz.asf").write_bytes(_shared("motion", "cmu_11.asf", limit=0)(tmp))
    return _amc_frames()


# (id, module, reader function, extension, valid-sample factory; a factory may write the
# companion file a format needs beside ``fuzz<ext>``, e.g. the AMC of an ASF)
CASES = [
    ("las", "las", "read_points", ".las", _written("las", "write_points", ".las", _cloud)),
    ("laz", "las", "read_points", ".laz", _written("las", "write_points", ".laz", _cloud)),
    (
        "ply-points-bin",
        "ply",
        "read_points",
        ".ply",
        _written("ply", "write_points", ".ply", _cloud),
    ),
    (
        "ply-points-ascii",
        "ply",
        "read_points",
        ".ply",
        _written("ply", "write_points", ".ply", _cloud, text=True),
    ),
    (
        "ply-graph",
        "ply",
        "read_graph",
        ".ply",
        _written("ply", "write_graph", ".ply", _graph, text=True),
    ),
    ("ply-graph-bin", "ply", "read_graph", ".ply", _written("ply", "write_graph", ".ply", _graph)),
    ("ply-mesh", "ply", "read_mesh", ".ply", _written("ply", "write_mesh", ".ply", _mesh)),
    ("xyz", "xyz", "read_points", ".xyz", _written("xyz", "write_points", ".xyz", _cloud)),
    ("csv", "xyz", "read_points", ".csv", _written("xyz", "write_points", ".csv", _cloud)),
    ("npy", "npy", "read_points", ".npy", _written("npy", "write_points", ".npy", _cloud)),
    ("mtg", "mtg", "read_graph", ".mtg", _written("mtg", "write_graph", ".mtg", _graph)),
    ("mtg-real", "mtg", "read_graph", ".mtg", _shared("trees", "plantscan3d_A3B4.mtg", limit=0)),
    ("obj", "obj", "read_mesh", ".obj", _written("obj", "write_mesh", ".obj", _mesh)),
    ("bvh", "bvh", "read_bvh", ".bvh", _text(BVH)),
    ("bvh-motion", "bvh", "read_motion", ".bvh", _text(BVH)),
    (
        "htr",
        "htr",
        "read_motion",
        ".htr",
        _shared("motion", "animal3d_egnaro_skel_anim.htr", limit=0),
    ),
    ("asf", "asf", "read_motion", ".asf", _asf_with_amc),
    ("amc", "asf", "read_motion", ".amc", _amc_with_asf),
    ("can", "caribu", "read_can", ".can", _written("caribu", "write_can", ".can", _mesh)),
    ("can-real", "caribu", "read_can", ".can", lambda tmp: _first_can(tmp)),
    ("svg", "svg_annotations", "read_annotations", ".svg", lambda tmp: _svg()),
    (
        "qsm-csv",
        "biomorph.tree.reference",
        "read_qsm_csv",
        ".csv",
        _shared("trees", "rtwig_QSM_simpleforest.csv", limit=0),
    ),
    ("laz-real", "las", "read_points", ".laz", _shared("trees", "treels_spruce.laz", limit=0)),
    ("las-real", "las", "read_points", ".las", _shared("trees", "archi_tree2.las", limit=0)),
    (
        "glb-summary",
        "gltf",
        "read_gltf_summary",
        ".glb",
        _written("gltf", "write_gltf", ".glb", lambda: _mesh()),
    ),
]


def _first_can(tmp: Path) -> bytes:
    folder = SHARED_DATA / "leaves" / "caribu"
    cans = sorted(folder.rglob("*.can")) if folder.exists() else []
    if not cans:
        pytest.skip(f"no real .can file under {folder}")
    return cans[0].read_bytes()[:60_000]


def _svg() -> bytes:
    from tests.creature.test_export_cli import SVG

    return SVG.encode()


#: readers with a known non-BiomorphError on fuzzed input, reported to their owners; kept
#: visible as xfail (non-strict, so the case turns into XPASS once fixed).
KNOWN_BUGS: dict[str, str] = {}


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One random corruption: truncation, byte flips, insertion, deletion, token damage."""
    b = bytearray(data)
    n = len(b)
    kind = rng.integers(0, 7)
    if kind == 0:  # truncate
        return bytes(b[: int(rng.integers(0, max(n, 1)))])
    if kind == 1:  # flip a few bytes
        for _ in range(int(rng.integers(1, 9))):
            if n:
                b[int(rng.integers(0, n))] = int(rng.integers(0, 256))
        return bytes(b)
    if kind == 2:  # insert random bytes
        pos = int(rng.integers(0, n + 1))
        return bytes(b[:pos]) + rng.bytes(int(rng.integers(1, 16))) + bytes(b[pos:])
    if kind == 3:  # delete a chunk
        pos = int(rng.integers(0, max(n, 1)))
        return bytes(b[:pos] + b[pos + int(rng.integers(1, 64)) :])
    if kind == 4:  # damage a digit into a letter or a special value
        digits = [i for i, c in enumerate(b) if 48 <= c <= 57]
        if digits:
            i = digits[int(rng.integers(0, len(digits)))]
            repl = [b"x", b"nan", b"inf", b"-", b".", b"1e999", b""][int(rng.integers(0, 7))]
            return bytes(b[:i]) + repl + bytes(b[i + 1 :])
        return bytes(b)
    if kind == 5:  # duplicate or drop a line
        lines = bytes(b).split(b"\n")
        if len(lines) > 1:
            k = int(rng.integers(0, len(lines)))
            if rng.random() < 0.5:
                lines.insert(k, lines[k])
            else:
                del lines[k]
        return b"\n".join(lines)
    # kind 6: overwrite a 4-byte window with extreme integers (binary headers, counts)
    if n >= 4:
        pos = int(rng.integers(0, n - 3))
        b[pos : pos + 4] = [(0xFF, 0xFF, 0xFF, 0x7F), (0, 0, 0, 0), (0xFF,) * 4][
            int(rng.integers(0, 3))
        ]
    return bytes(b)


def non_finite_fields(result: object) -> list[str]:
    """Names of the numeric fields of a reader's result that hold NaN or inf."""
    bad = []
    for name in (
        "xyz",
        "position",
        "vertices",
        "rotation",
        "root_position",
        "offset",
        "radius",
        "joint_translation",
    ):
        val = getattr(result, name, None)
        if val is None and name == "offset":
            val = getattr(getattr(result, "skeleton", None), "offset", None)
        if isinstance(val, np.ndarray) and val.dtype.kind == "f" and not np.isfinite(val).all():
            bad.append(name)
    return bad


def fuzz_case(name: str, folder: str) -> None:
    """Run the mutations of case ``name`` in this process (the child of the test)."""
    case = next(c for c in CASES if c[0] == name)
    _, module, func, ext, make = case
    tmp_path = Path(folder)
    reader = getattr(importlib.import_module(_module_name(module)), func)
    data = make(tmp_path)
    reader_input = tmp_path / f"fuzz{ext}"
    reader_input.write_bytes(data)
    reader(reader_input)  # the unmutated sample must read
    rng = np.random.default_rng(sum(map(ord, name)))
    iterations = ITERATIONS if len(data) < 100_000 else ITERATIONS // 3  # big real files
    for it in range(iterations):
        mutated = mutate(data, rng)
        reader_input.write_bytes(mutated)
        (tmp_path / "current").write_bytes(mutated)  # what was being read if we die
        try:
            result = reader(reader_input)
        except BiomorphError as exc:
            assert str(exc), "error message must not be empty"
        except Exception as exc:  # noqa: BLE001 - this is what the test is looking for
            keep = tmp_path / f"crash_{it}{ext}"
            keep.write_bytes(mutated)
            raise AssertionError(
                f"{module}.{func} raised {type(exc).__name__}: {exc} on "
                f"mutation {it} (saved at {keep})"
            ) from None
        else:
            bad = non_finite_fields(result)
            if bad:
                keep = tmp_path / f"nonfinite_{it}{ext}"
                keep.write_bytes(mutated)
                raise AssertionError(
                    f"{module}.{func} accepted a file giving NaN/inf in {bad} "
                    f"on mutation {it} (saved at {keep}); expected a "
                    "FormatError"
                )


CHILD = """
import sys
import pytest
from tests.io.test_fuzz import fuzz_case
print("READY", flush=True)
for line in sys.stdin:
    name, folder = line.rstrip("\\n").split("\\t")
    try:
        fuzz_case(name, folder)
    except pytest.skip.Exception as exc:
        print("SKIP", " ".join(str(exc).split()), flush=True)
    except AssertionError as exc:
        print("FAIL", " ".join(str(exc).split()), flush=True)
    else:
        print("OK", flush=True)
"""


class FuzzChild:
    """A long-lived child process that runs fuzz cases on request (imports once); a case
    that kills or hangs it fails, and the next case gets a fresh child."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None

    def _start(self) -> None:
        root = Path(__file__).resolve().parents[2]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), *sys.path])}
        self.proc = subprocess.Popen(
            [sys.executable, "-c", CHILD],
            env=env,
            text=True,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        assert self._line(120) == "READY", self._died()

    def _line(self, seconds: float) -> str | None:
        import selectors

        assert self.proc is not None and self.proc.stdout is not None
        with selectors.DefaultSelector() as sel:
            sel.register(self.proc.stdout, selectors.EVENT_READ)
            if not sel.select(seconds):
                return None
        line = self.proc.stdout.readline()
        return line.strip() if line else ""

    def _died(self) -> str:
        assert self.proc is not None
        code = self.proc.wait(10)
        tail = "\n".join(
            (self.proc.stderr.read() if self.proc.stderr else "").strip().splitlines()[-6:]
        )
        self.proc = None
        how = f"was killed by signal {-code}" if code < 0 else f"exited with {code}"
        return f"the reading process {how}\n{tail}"

    def run(self, name: str, folder: Path) -> tuple[str, str]:
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        assert self.proc is not None and self.proc.stdin is not None
        self.proc.stdin.write(f"{name}\t{folder}\n")
        self.proc.stdin.flush()
        line = self._line(CASE_SECONDS)
        if line is None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None
            return "FAIL", f"hung (> {CASE_SECONDS} s)"
        if line == "":
            return "FAIL", self._died()
        status, _, message = line.partition(" ")
        return status, message

    def close(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()


@pytest.fixture(scope="module")
def child():
    c = FuzzChild()
    yield c
    c.close()


@pytest.mark.parametrize(
    "case",
    [
        pytest.param(
            c,
            id=c[0],
            marks=[pytest.mark.xfail(reason=KNOWN_BUGS[c[0]], strict=False)]
            if c[0] in KNOWN_BUGS
            else [],
        )
        for c in CASES
    ],
)
def test_reader_only_raises_biomorph_errors(tmp_path, child, case):
    name, module, func = case[:3]
    try:
        mod = importlib.import_module(_module_name(module))
    except ModuleNotFoundError:
        pytest.skip(f"{_module_name(module)} does not exist yet")
    if getattr(mod, func, None) is None:
        pytest.skip(f"{_module_name(module)}.{func} does not exist yet")
    status, message = child.run(name, tmp_path)
    if status == "SKIP":
        pytest.skip(message)
    if status != "OK":
        pytest.fail(
            f"{module}.{func}: {message}; input being read is saved at {tmp_path / 'current'}"
        )
