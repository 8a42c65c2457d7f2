"""Box2D v3 (erincatto/box2d, C, MIT) as a bench peer, built from a source the user gives.

Box2D v3 has no Python binding here, so the peer is a small C driver (box2d_v3_scenes.c, beside
this file) linked against Box2D: it reads one scene exported by `export_scene` (the bench's own
`BenchScene`, every number in %.17g, vertices re-centred on the area centroid as for the other
peers), takes the scene's warm-up and timed steps in one compiled process and writes the start
and final states of every body; the worker measures quality on those with bench/quality.py, as
for every engine.

Source: `python -m bench --box2d-v3 SRC` or the environment variable ISAAC_BOX2D_V3 (the
command line wins); SRC is a Box2D v3 source tree (with include/box2d/box2d.h) or its .tar.gz.
No source: the row is not run and the results say so in one line. A source that is not there or
is not Box2D: `SourceError` (the suite prints one line, exit 2).

Build (`ensure_built`), once per source and driver, into
`$XDG_CACHE_HOME/isaac/box2d-v3/<hash>` (`~/.cache/...` without XDG_CACHE_HOME), where <hash>
covers the source's bytes, the driver's and the build flags below, so a changed source or
driver builds afresh and nothing is written inside the repository. Steps: unpack (a tarball),
configure and build Box2D with cmake (Release, gcc, static, AVX2, validation and profiling off,
float32; Box2D's own CMakeLists adds -ffp-contract=off, its determinism flag), compile the driver
with gcc (-O2 -ffp-contract=off), check it runs. A step that fails raises `BuildError`, naming
the step and its log file. The build goes into a temporary folder renamed into place at the
end, so a half-built folder is never used.

Settings (the row): 4 sub-steps (Box2D's default), sleeping off, 1 worker with no task system,
Box2D's defaults otherwise (soft step: contact hertz 30, damping ratio 10, push speed 3 m/s,
5 mm linear slop, continuous collision against static bodies).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tarfile
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.geometry import local_vertices
from isaac.scene import Scene

ENV = "ISAAC_BOX2D_V3"
DRIVER = Path(__file__).with_name("box2d_v3_scenes.c")
SUBSTEPS = 4  # Box2D v3's default sub-step count
SETTINGS = f"{SUBSTEPS} sub-steps (soft step), float32, 1 worker, no sleeping, AVX2"
NO_SOURCE_NOTE = f"Box2D v3: not run (no source: --box2d-v3 SRC or {ENV})"
SCENE_HEADER = "isaac-box2d-v3-scene 1"

CMAKE_OPTIONS = (
    "-DCMAKE_BUILD_TYPE=Release",
    "-DCMAKE_C_COMPILER=gcc",
    "-DBUILD_SHARED_LIBS=OFF",
    "-DBOX2D_AVX2=ON",
    "-DBOX2D_VALIDATE=OFF",
    "-DBOX2D_PROFILE=OFF",
    "-DBOX2D_DOUBLE_PRECISION=OFF",
    "-DBOX2D_SAMPLES=OFF",
    "-DBOX2D_BENCHMARKS=OFF",
    "-DBOX2D_UNIT_TESTS=OFF",
    "-DBOX2D_DOCS=OFF",
)
DRIVER_FLAGS = ("-std=c17", "-O2", "-DNDEBUG", "-ffp-contract=off", "-Wall", "-Wextra")
BUILD_JOBS = "2"


class SourceError(ValueError):
    """SRC is not there, or is neither a Box2D v3 source tree nor a .tar.gz of one."""


class BuildError(RuntimeError):
    """A build step failed; `step` names it, `log` is the file with its output."""

    def __init__(self, step: str, detail: str, log: Path) -> None:
        super().__init__(f"Box2D v3: not run (build failed at {step}: {detail}; log: {log})")
        self.step, self.log = step, log


@dataclass(frozen=True)
class Build:
    """A built driver: `binary` (the executable), `version` (Box2D's, "3.2.0"), `source`."""

    binary: Path
    version: str
    source: Path


def source_from(arg: str | None) -> Path | None:
    """The source named by `--box2d-v3` (`arg`), else by ISAAC_BOX2D_V3, else None; checked:
    a folder with include/box2d/box2d.h and CMakeLists.txt, or a readable .tar.gz."""
    origin, value = ("--box2d-v3", arg) if arg else (ENV, os.environ.get(ENV, ""))
    if not value:
        return None
    path = Path(value).expanduser()
    if path.is_dir():
        if not (path / "include" / "box2d" / "box2d.h").is_file():
            raise SourceError(
                f"{origin} {value}: not a Box2D v3 source tree (no include/box2d/box2d.h)"
            )
        if not (path / "CMakeLists.txt").is_file():
            raise SourceError(f"{origin} {value}: not a Box2D v3 source tree (no CMakeLists.txt)")
        return path.resolve()
    if path.is_file():
        if not value.endswith((".tar.gz", ".tgz")) or not tarfile.is_tarfile(path):
            raise SourceError(f"{origin} {value}: not a Box2D v3 source tree or .tar.gz")
        return path.resolve()
    raise SourceError(f"{origin} {value}: no such file or folder")


def cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "isaac" / "box2d-v3"


def _source_files(src: Path) -> list[Path]:
    """A tree's files in sorted order, leaving out version control and build folders."""
    skip = {".git", "build", "out"}
    files = []
    for folder, dirs, names in os.walk(src):
        dirs[:] = sorted(d for d in dirs if d not in skip and not d.startswith("build"))
        files += [Path(folder) / n for n in sorted(names)]
    return files


def build_hash(src: Path) -> str:
    """16 hex digits of SHA-256 over the build flags, the driver and the source's bytes."""
    h = hashlib.sha256()
    h.update(repr((CMAKE_OPTIONS, DRIVER_FLAGS)).encode())
    h.update(DRIVER.read_bytes())
    if src.is_file():
        h.update(src.read_bytes())
    else:
        for path in _source_files(src):
            h.update(str(path.relative_to(src)).encode() + b"\0")
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _unpacked_root(folder: Path) -> Path:
    """The folder of an unpacked tarball that holds include/box2d/box2d.h (top or one down)."""
    for candidate in (folder, *sorted(p for p in folder.iterdir() if p.is_dir())):
        if (candidate / "include" / "box2d" / "box2d.h").is_file():
            return candidate
    raise FileNotFoundError("no include/box2d/box2d.h in the tarball")


def _step(name: str, cmd: list[str], log: Path, cwd: Path | None = None) -> str:
    """Run one build step, its output appended to `log`; its stdout, or BuildError."""
    if shutil.which(cmd[0]) is None:
        raise BuildError(name, f"{cmd[0]} not found on PATH", log)
    with open(log, "a") as f:
        f.write(f"$ {' '.join(cmd)}\n")
        f.flush()
        proc = subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=f, text=True)
        f.write(proc.stdout)
    if proc.returncode != 0:
        raise BuildError(name, f"exit {proc.returncode}", log)
    return proc.stdout


def ensure_built(src: Path, *, cache: Path | None = None) -> Build:
    """The driver built against `src`, from the cache folder when it is there (see the module
    docstring); BuildError if a step fails."""
    root = cache or cache_root()
    folder = root / build_hash(src)
    info = folder / "build.json"
    if info.is_file():
        data = json.loads(info.read_text())
        return Build(folder / "box2d_v3_scenes", data["version"], src)
    root.mkdir(parents=True, exist_ok=True)
    log = root / f"{folder.name}.log"
    log.write_text(f"Box2D v3 build of {src}\n")
    work = Path(tempfile.mkdtemp(prefix=f"{folder.name}.partial-", dir=root))
    try:
        if src.is_file():
            try:
                with tarfile.open(src) as tar:
                    tar.extractall(work / "src", filter="data")
                tree = _unpacked_root(work / "src")
            except (OSError, tarfile.TarError) as exc:
                raise BuildError("unpack", str(exc), log) from None
        else:
            tree = src
        lib_build = work / "box2d-build"
        _step(
            "configure (cmake)",
            ["cmake", "-S", str(tree), "-B", str(lib_build), *CMAKE_OPTIONS],
            log,
        )
        _step(
            "build (cmake --build)",
            ["cmake", "--build", str(lib_build), "--target", "box2d", "-j", BUILD_JOBS],
            log,
        )
        binary = work / "box2d_v3_scenes"
        library = lib_build / "src" / "libbox2d.a"
        compile_cmd = ["gcc", *DRIVER_FLAGS, f"-I{tree / 'include'}", "-o", str(binary)]
        _step("compile the driver (gcc)", [*compile_cmd, str(DRIVER), str(library), "-lm"], log)
        version = _step("check the driver (--version)", [str(binary), "--version"], log).strip()
        shutil.rmtree(work / "src", ignore_errors=True)
        shutil.rmtree(lib_build, ignore_errors=True)
        shutil.copy(log, work / "build.log")
        (work / "build.json").write_text(json.dumps(dict(version=version, source=str(src))))
        try:
            work.rename(folder)
        except OSError:  # another process finished the same build first: use that one
            shutil.rmtree(work, ignore_errors=True)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    log.unlink(missing_ok=True)
    return Build(folder / "box2d_v3_scenes", version, src)


# ---- the scene, exported --------------------------------------------------------------------


def _g(x: float) -> str:
    """A double in %.17g: read back by strtod, the same double."""
    return format(float(x), ".17g")


def export_scene(scene: Scene, warmup_steps: int, timed_steps: int) -> str:
    """The scene as the driver's text format (box2d_v3_scenes.c's header comment)."""
    w = scene.world
    lines = [
        SCENE_HEADER,
        f"gravity {_g(w.gravity[0])} {_g(w.gravity[1])}",
        f"dt {_g(w.dt)}",
        f"friction_on {int(bool(w.friction))}",
        f"steps {warmup_steps} {timed_steps}",
        f"bodies {len(scene.bodies)}",
    ]
    for b in scene.bodies:
        v = local_vertices(b.vertices)
        fields = [str(int(b.concrete)), _g(b.density), _g(b.friction), _g(b.restitution)]
        fields += [_g(b.position[0]), _g(b.position[1]), _g(b.angle)]
        fields += [_g(b.velocity[0]), _g(b.velocity[1]), _g(b.angular_velocity), str(len(v))]
        fields += [_g(c) for p in v for c in p]
        lines.append(" ".join(fields))
    return "\n".join(lines) + "\n"


class Box2DV3Engine:
    """The bench's adapter for Box2D v3: it runs a whole scene in the driver's process
    (`run_scene`), then `start()`, `poses()` and `velocities()` give the states it wrote, in
    scene body order, positions being centres of mass (m)."""

    name = "box2d-v3"
    settings = SETTINGS

    def __init__(self, scene: Scene, build: Build | None = None) -> None:
        if build is None:
            src = source_from(None)
            if src is None:
                raise SourceError(NO_SOURCE_NOTE)
            build = ensure_built(src)
        self.scene = scene
        self.build = build
        self.version = build.version
        self._states: np.ndarray | None = None

    def run_scene(self, warmup_steps: int, timed_steps: int, substeps: int = SUBSTEPS) -> dict:
        """Build, warm up and time the scene in the driver; its JSON figures (ms_per_step over
        the timed block, build_s, RSS in bytes after reading the scene, building, warming up)."""
        with tempfile.TemporaryDirectory(prefix="isaac-box2d-v3-") as tmp:
            scene_file, poses_file = Path(tmp) / "scene.txt", Path(tmp) / "poses.txt"
            scene_file.write_text(export_scene(self.scene, warmup_steps, timed_steps))
            cmd = [str(self.build.binary), str(scene_file), str(poses_file)]
            proc = subprocess.run(
                [*cmd, "--substeps", str(substeps)], capture_output=True, text=True
            )
            if proc.returncode != 0:
                tail = (proc.stderr or "").strip().splitlines()[-1:] or [f"exit {proc.returncode}"]
                raise RuntimeError(f"box2d_v3_scenes: {tail[0]}")
            self._states = np.loadtxt(poses_file, ndmin=2)
        return json.loads(proc.stdout.strip().splitlines()[-1])

    def _columns(self, first: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if self._states is None:
            raise RuntimeError("Box2DV3Engine: run_scene first")
        s = self._states[:, first : first + 6]
        return s[:, 0:2], s[:, 2], s[:, 3:5], s[:, 5]

    def start(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(positions (n, 2), angles (n,), velocities (n, 2)) after building, before any step."""
        pos, ang, vel, _ = self._columns(0)
        return pos, ang, vel

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        pos, ang, _, _ = self._columns(6)
        return pos, ang

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        _, _, vel, omega = self._columns(6)
        return vel, omega
