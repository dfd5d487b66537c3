"""``meshlab-sharp plugin``: build and install the C++ MeshLab 2020.09 filter plugin.

Debian ships MeshLab 2020.09 without headers; they come from Debian's source package
(``apt-get source meshlab``), which is fetched once into the cache folder. The plugin is
built with CMake against Debian's ``libmeshlab-common.so`` and installed into Debian's
plugin folder, or into a private MeshLab root (copies of ``meshlab`` and
``meshlabserver`` beside links to the system plugins and ours), which needs no write
access to the system once the Debian packages are there.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

from .cache import cache_dir
from .errors import MeshlabSharpError

#: Debian packages the plugin needs to build and run (headless runs use Xvfb).
PACKAGES = (
    "meshlab",
    "g++",
    "make",
    "cmake",
    "dpkg-dev",
    "qtbase5-dev",
    "libqt5opengl5-dev",
    "libglew-dev",
    "libeigen3-dev",
    "xvfb",
    "xauth",
)
#: The Debian source package whose headers the plugin compiles against.
SOURCE_PACKAGE = "meshlab"
SOURCE_FOLDER = "meshlab-2020.09+dfsg1"
SYSTEM_LIB = Path("/usr/lib/x86_64-linux-gnu/meshlab")
PLUGIN_FILE = "libfilter_sharp_features.so"
FILTER_NAME = "Select Sharp Features (Projected Distance)"
CURVES_FILTER_NAME = "Extract Sharp Feature Curves"
_DEB_SRC = Path("/etc/apt/sources.list.d/meshlab-sharp-src.sources")


def add_plugin_command(subparsers: argparse._SubParsersAction) -> None:
    """Register ``meshlab-sharp plugin {install,deps}`` on the CLI's subparsers."""
    plugin = subparsers.add_parser(
        "plugin",
        help="build and install the MeshLab 2020.09 filter plugin",
        description="Build the C++ filter plugin against Debian's MeshLab 2020.09 and install it.",
    )
    sub = plugin.add_subparsers(dest="plugin_command", metavar="ACTION")
    sub.required = True
    install = sub.add_parser(
        "install",
        help="install the Debian packages, fetch the headers, build, install",
        description="Install the Debian packages the plugin needs (apt-get update first), "
        "fetch MeshLab's Debian source package for the headers if absent, build with CMake, "
        f"and install into {SYSTEM_LIB}/plugins, or with --root into a private MeshLab root.",
    )
    install.add_argument(
        "--root",
        metavar="DIR",
        help="build a private MeshLab root at DIR (DIR/bin/meshlab and DIR/bin/meshlabserver "
        "load the plugin) instead of installing into the system",
    )
    _add_build_options(install)
    install.set_defaults(func=_run_install)
    deps = sub.add_parser(
        "deps",
        help="only install the Debian packages and fetch the MeshLab headers",
    )
    _add_build_options(deps)
    deps.set_defaults(func=_run_deps)


def _add_build_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--source-dir",
        metavar="DIR",
        help=f"unpacked MeshLab source package (default: the cache folder's {SOURCE_FOLDER})",
    )
    parser.add_argument(
        "--build-dir",
        metavar="DIR",
        help="CMake build folder (default: one per plugin source tree in the cache folder)",
    )
    parser.add_argument(
        "--no-apt", action="store_true", help="do not run apt-get; fail if a package is missing"
    )


def _run_deps(args: argparse.Namespace) -> int:
    ensure_packages(use_apt=not args.no_apt)
    source = ensure_source(Path(args.source_dir) if args.source_dir else None, not args.no_apt)
    print(f"plugin: Debian packages present; MeshLab headers in {source}")
    return 0


def _run_install(args: argparse.Namespace) -> int:
    ensure_packages(use_apt=not args.no_apt)
    source = ensure_source(Path(args.source_dir) if args.source_dir else None, not args.no_apt)
    sources = plugin_sources()
    build_dir = Path(args.build_dir) if args.build_dir else default_build_dir(sources)
    library = build(source, build_dir, sources)
    if args.root:
        root = make_private_root(Path(args.root), library)
        print(f"plugin: installed into the private MeshLab root {root}")
        print(f"plugin: run {root / 'bin' / 'meshlab'} or {root / 'bin' / 'meshlabserver'}")
    else:
        dest = install_system(library)
        print(f"plugin: installed {dest}; Debian's meshlab and meshlabserver now list")
        print(f"plugin: Filters > Selection > {FILTER_NAME}")
        print(
            f"plugin: Filters > Remeshing, Simplification and Reconstruction > {CURVES_FILTER_NAME}"
        )
    return 0


def default_build_dir(sources: Path) -> Path:
    """The CMake build folder of one plugin source tree: ``build-<hash of its path>`` in
    the cache, so that two checkouts (or installs) never share a CMake cache."""
    key = hashlib.sha256(str(sources.resolve()).encode()).hexdigest()[:16]
    return cache_dir() / f"build-{key}"


def plugin_sources() -> Path:
    """The plugin's sources: ``_sources/meshlab_plugin_cpp`` inside the installed package
    (a wheel), or ``meshlab_plugin_cpp`` beside the package (a git checkout, editable
    install); the native library's sources lie beside them (``native``)."""
    package = Path(__file__).resolve().parent
    candidates = (
        package / "_sources" / "meshlab_plugin_cpp",
        package.parent / "meshlab_plugin_cpp",
    )
    for folder in candidates:
        if (folder / "CMakeLists.txt").is_file():
            return folder
    raise MeshlabSharpError(
        f"the plugin sources are missing (looked in {' and '.join(map(str, candidates))}); "
        "reinstall meshlab-sharp"
    )


def missing_packages() -> list[str]:
    """Debian packages of :data:`PACKAGES` that are not installed."""
    missing = []
    for name in PACKAGES:
        proc = subprocess.run(
            ["dpkg-query", "-W", "-f=${Status}", name],
            capture_output=True,
            text=True,
            check=False,
        )
        if "install ok installed" not in proc.stdout:
            missing.append(name)
    return missing


def ensure_packages(*, use_apt: bool) -> None:
    """Install the missing Debian packages with apt-get (``apt-get update`` first)."""
    if shutil.which("dpkg-query") is None:
        raise MeshlabSharpError("the plugin is built for Debian's MeshLab: dpkg-query not found")
    missing = missing_packages()
    if not missing:
        return
    if not use_apt:
        raise MeshlabSharpError(f"missing Debian packages: {' '.join(missing)}")
    print(f"plugin: installing Debian packages: {' '.join(missing)}", file=sys.stderr)
    _apt(["update", "-qq"])
    _apt(["install", "-y", "-qq", "--no-install-recommends", *missing])


def _apt(arguments: list[str]) -> None:
    command = ["apt-get", *arguments]
    if os.geteuid() != 0:
        if shutil.which("sudo") is None:
            raise MeshlabSharpError(f"run as root: {' '.join(command)} needs root rights")
        command = ["sudo", *command]
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    _check_call(command, env=env)


def ensure_source(source_dir: Path | None, use_apt: bool) -> Path:
    """The unpacked MeshLab 2020.09 source package, fetched into the cache if absent."""
    if source_dir is not None:
        if not (source_dir / "src" / "common" / "interfaces.h").is_file():
            raise MeshlabSharpError(f"{source_dir}: not an unpacked MeshLab 2020.09 source tree")
        return source_dir
    target = cache_dir() / SOURCE_FOLDER
    if (target / "src" / "common" / "interfaces.h").is_file():
        return target
    if not use_apt:
        raise MeshlabSharpError(f"MeshLab headers not found in {target} (and --no-apt given)")
    _ensure_deb_src()
    target.parent.mkdir(parents=True, exist_ok=True)
    print(f"plugin: fetching Debian's {SOURCE_PACKAGE} source package into {target.parent}")
    _check_call(["apt-get", "source", "-qq", SOURCE_PACKAGE], cwd=target.parent)
    if not (target / "src" / "common" / "interfaces.h").is_file():
        raise MeshlabSharpError(f"apt-get source {SOURCE_PACKAGE} did not unpack {target}")
    return target


def _ensure_deb_src() -> None:
    """Add a deb-src entry beside Debian 12's debian.sources, unless one exists."""
    lists = Path("/etc/apt/sources.list.d")
    texts = [p.read_text(errors="replace") for p in lists.glob("*.sources")]
    legacy = Path("/etc/apt/sources.list")
    if legacy.is_file():
        texts.append(legacy.read_text(errors="replace"))
    if any("deb-src" in t for t in texts):
        return
    debian = lists / "debian.sources"
    if not debian.is_file():
        raise MeshlabSharpError(
            "no deb-src entry and no /etc/apt/sources.list.d/debian.sources to derive one from"
        )
    entry = debian.read_text().replace("Types: deb\n", "Types: deb-src\n")
    if os.geteuid() != 0:
        raise MeshlabSharpError(f"run as root to add {_DEB_SRC} (a deb-src entry)")
    _DEB_SRC.write_text(entry)
    _apt(["update", "-qq"])


def build(source: Path, build_dir: Path, sources: Path) -> Path:
    """Configure and build the plugin with CMake; return the built library.

    ``source``: the unpacked MeshLab source package (headers); ``sources``: the plugin's
    sources (:func:`plugin_sources`)."""
    build_dir.mkdir(parents=True, exist_ok=True)
    _check_call(
        [
            "cmake",
            "-S",
            str(sources),
            "-B",
            str(build_dir),
            f"-DMESHLAB_SOURCE_DIR={source}",
            "-DCMAKE_BUILD_TYPE=Release",
        ],
    )
    _check_call(["cmake", "--build", str(build_dir), "-j", str(min(os.cpu_count() or 1, 2))])
    library = build_dir / PLUGIN_FILE
    if not library.is_file():
        raise MeshlabSharpError(f"the build did not produce {library}")
    return library


def install_system(library: Path) -> Path:
    """Copy the plugin into Debian's MeshLab plugin folder (atomically)."""
    dest = SYSTEM_LIB / "plugins" / PLUGIN_FILE
    if not os.access(dest.parent, os.W_OK):
        raise MeshlabSharpError(f"cannot write {dest.parent}: run as root, or use --root DIR")
    tmp = dest.with_suffix(".so.part")
    shutil.copy2(library, tmp)
    os.replace(tmp, dest)
    return dest


def make_private_root(root: Path, library: Path) -> Path:
    """A MeshLab root whose ``bin/meshlab`` and ``bin/meshlabserver`` load the plugin.

    Debian's MeshLab finds plugins only in ``<exe dir>/../lib/x86_64-linux-gnu/meshlab/
    plugins``, and Qt resolves a symlinked executable to its target, so the binaries are
    copied; the libraries and the system plugins are linked.
    """
    root = root.resolve()
    bindir = root / "bin"
    libdir = root / "lib" / "x86_64-linux-gnu" / "meshlab"
    plugins = libdir / "plugins"
    for folder in (bindir, plugins):
        folder.mkdir(parents=True, exist_ok=True)
    for exe in ("meshlab", "meshlabserver"):
        src = Path("/usr/bin") / exe
        if not src.is_file():
            raise MeshlabSharpError(f"{src} not found: install Debian's meshlab package")
        shutil.copy2(src, bindir / exe)
    _relink(libdir / "libmeshlab-common.so", SYSTEM_LIB / "libmeshlab-common.so")
    for system_plugin in sorted((SYSTEM_LIB / "plugins").glob("*.so")):
        if system_plugin.name != PLUGIN_FILE:
            _relink(plugins / system_plugin.name, system_plugin)
    shutil.copy2(library, plugins / PLUGIN_FILE)
    return root


def _relink(link: Path, target: Path) -> None:
    if link.is_symlink() or link.exists():
        link.unlink()
    link.symlink_to(target)


def _check_call(command: list[str], **kwargs: object) -> None:
    """Run a command; its failure becomes a one-line error with the tail of its output."""
    try:
        proc = subprocess.run(command, capture_output=True, text=True, check=False, **kwargs)
    except FileNotFoundError:
        raise MeshlabSharpError(f"{command[0]} not found") from None
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise MeshlabSharpError(
            f"{' '.join(command[:3])} failed (exit {proc.returncode}): {' | '.join(tail)}"
        )
