"""``meshlab-sharp plugin``: build and install the C++ MeshLab 2020.09 filter plugin.

Debian ships MeshLab 2020.09 without headers; they come from Debian's source package
(``apt-get source meshlab``), which is fetched once into the cache folder. The plugin is
built with CMake against Debian's ``libmeshlab-common.so`` and installed into Debian's
plugin folder, or into a private MeshLab root (copies of ``meshlab`` and
``meshlabserver`` beside links to the system plugins and ours), which needs no write
access to the system once the Debian packages are there.

Every step says what it does on stderr (``plugin: ...`` lines), and nothing on the
system changes without a line saying so. The apt sources are changed only on request
(``--allow-deb-src``: a deb-src entry, needed when apt has none, to fetch the headers),
and ``meshlab-sharp plugin uninstall`` takes the plugin and that entry away again.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import time
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
_APT_LISTS = Path("/etc/apt/sources.list.d")
_APT_LEGACY = Path("/etc/apt/sources.list")
_DEB_SRC = _APT_LISTS / "meshlab-sharp-src.sources"


def add_plugin_command(subparsers: argparse._SubParsersAction) -> None:
    """Register ``meshlab-sharp plugin {install,deps,uninstall,examples}`` on the CLI's
    subparsers."""
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
        description="Install the Debian packages the plugin needs (apt-get update first) "
        "and fetch MeshLab's Debian source package for the headers if absent; build nothing.",
    )
    _add_build_options(deps, build_dir=False)
    deps.set_defaults(func=_run_deps)
    uninstall = sub.add_parser(
        "uninstall",
        help="remove the installed plugin (and the deb-src entry --allow-deb-src added)",
        description=f"Remove {SYSTEM_LIB}/plugins/{PLUGIN_FILE} and {_DEB_SRC} if present, "
        "or with --root the private MeshLab root's files. The Debian packages stay.",
    )
    uninstall.add_argument(
        "--root", metavar="DIR", help="remove the private MeshLab root made at DIR instead"
    )
    uninstall.set_defaults(func=_run_uninstall)
    examples = sub.add_parser(
        "examples",
        help="print the folder of the example MeshLab scripts (.mlx)",
        description="Print the folder holding the example .mlx filter scripts, one line per "
        "script, and how meshlabserver runs one.",
    )
    examples.set_defaults(func=_run_examples)


def _add_build_options(parser: argparse.ArgumentParser, *, build_dir: bool = True) -> None:
    parser.add_argument(
        "--source-dir",
        metavar="DIR",
        help=f"unpacked MeshLab source package (default: the cache folder's {SOURCE_FOLDER})",
    )
    if build_dir:
        parser.add_argument(
            "--build-dir",
            metavar="DIR",
            help="CMake build folder (default: one per plugin source tree in the cache folder)",
        )
    parser.add_argument(
        "--no-apt", action="store_true", help="do not run apt-get; fail if a package is missing"
    )
    parser.add_argument(
        "--allow-deb-src",
        action="store_true",
        help=f"when apt has no deb-src entry for MeshLab's headers, add {_DEB_SRC} (plugin "
        "uninstall removes it); without it the apt sources are never changed",
    )


def _run_deps(args: argparse.Namespace) -> int:
    ensure_packages(use_apt=not args.no_apt)
    source = ensure_source(
        Path(args.source_dir) if args.source_dir else None,
        not args.no_apt,
        allow_deb_src=args.allow_deb_src,
    )
    print(f"plugin: Debian packages present; MeshLab headers in {source}")
    return 0


def _run_install(args: argparse.Namespace) -> int:
    ensure_packages(use_apt=not args.no_apt)
    source = ensure_source(
        Path(args.source_dir) if args.source_dir else None,
        not args.no_apt,
        allow_deb_src=args.allow_deb_src,
    )
    sources = plugin_sources()
    build_dir = Path(args.build_dir) if args.build_dir else default_build_dir(sources)
    library = build(source, build_dir, sources)
    if args.root:
        say(f"making the private MeshLab root {Path(args.root).resolve()}")
        root = make_private_root(Path(args.root), library)
        print(f"plugin: installed into the private MeshLab root {root}")
        print(f"plugin: run {root / 'bin' / 'meshlab'} or {root / 'bin' / 'meshlabserver'}")
    else:
        say(f"copying the plugin into {SYSTEM_LIB / 'plugins'}")
        dest = install_system(library)
        print(f"plugin: installed {dest}; Debian's meshlab and meshlabserver now list")
        print(f"plugin: Filters > Selection > {FILTER_NAME}")
        print(
            f"plugin: Filters > Remeshing, Simplification and Reconstruction > {CURVES_FILTER_NAME}"
        )
    print("plugin: example scripts: meshlab-sharp plugin examples; undo: meshlab-sharp plugin "
          f"uninstall{' --root ' + str(args.root) if args.root else ''}")  # fmt: skip
    return 0


def _run_uninstall(args: argparse.Namespace) -> int:
    removed = remove_private_root(Path(args.root)) if args.root else uninstall_system()
    for path in removed:
        print(f"plugin: removed {path}")
    if not removed:
        print("plugin: nothing to remove: the plugin is not installed there")
    if not args.root:
        print("plugin: the Debian packages stay installed (remove them with apt-get if unwanted)")
    return 0


def _run_examples(args: argparse.Namespace) -> int:
    folder = examples_dir()
    print(folder)
    for script in sorted(folder.glob("*.mlx")):
        print(f"  {script.name}")
    print(
        f"run one: xvfb-run -a meshlabserver -i in.ply -o out.ply -m vq vf vc -s "
        f"{folder / 'sharp_features_default.mlx'}"
    )
    print(
        "meshlabserver may print 'no additional memory available!!!': MeshLab's GPU memory "
        "budget for drawing, read from the settings the MeshLab GUI writes on its first "
        "start, is 0 until then; nothing is drawn and the results are not affected"
    )
    return 0


def say(message: str) -> None:
    """One progress line on stderr, ``plugin: message``, flushed at once."""
    print(f"plugin: {message}", file=sys.stderr, flush=True)


def examples_dir() -> Path:
    """The folder of the example ``.mlx`` scripts, in the installed package or the
    checkout (the only place that knows where they are shipped)."""
    return plugin_sources() / "examples"


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
    say(f"installing Debian packages with apt-get (apt-get update first): {' '.join(missing)}")
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


def ensure_source(source_dir: Path | None, use_apt: bool, *, allow_deb_src: bool = False) -> Path:
    """The unpacked MeshLab 2020.09 source package, fetched into the cache if absent
    (adding a deb-src entry to apt's sources first only when ``allow_deb_src``)."""
    if source_dir is not None:
        if not (source_dir / "src" / "common" / "interfaces.h").is_file():
            raise MeshlabSharpError(f"{source_dir}: not an unpacked MeshLab 2020.09 source tree")
        return source_dir
    target = cache_dir() / SOURCE_FOLDER
    if (target / "src" / "common" / "interfaces.h").is_file():
        return target
    if not use_apt:
        raise MeshlabSharpError(f"MeshLab headers not found in {target} (and --no-apt given)")
    _ensure_deb_src(allow=allow_deb_src)
    target.parent.mkdir(parents=True, exist_ok=True)
    say(f"downloading Debian's {SOURCE_PACKAGE} source package (about 12 MB) into {target.parent}")
    _check_call(["apt-get", "source", "-qq", SOURCE_PACKAGE], cwd=target.parent)
    if not (target / "src" / "common" / "interfaces.h").is_file():
        raise MeshlabSharpError(f"apt-get source {SOURCE_PACKAGE} did not unpack {target}")
    return target


def _ensure_deb_src(*, allow: bool, lists: Path = _APT_LISTS, legacy: Path = _APT_LEGACY) -> None:
    """Add a deb-src entry beside Debian 12's debian.sources, unless one exists; only
    when ``allow`` (``--allow-deb-src``): otherwise a missing entry is an error saying
    so."""
    texts = [p.read_text(errors="replace") for p in lists.glob("*.sources")]
    if legacy.is_file():
        texts.append(legacy.read_text(errors="replace"))
    if any("deb-src" in t for t in texts):
        return
    if not allow:
        raise MeshlabSharpError(
            "MeshLab's headers come from Debian's source package, and apt has no deb-src "
            f"entry: rerun with --allow-deb-src to add {_DEB_SRC} (plugin uninstall removes "
            "it), or give --source-dir DIR (an unpacked meshlab source package)"
        )
    debian = lists / "debian.sources"
    if not debian.is_file():
        raise MeshlabSharpError(f"no deb-src entry and no {debian} to derive one from")
    entry = debian.read_text().replace("Types: deb\n", "Types: deb-src\n")
    if os.geteuid() != 0:
        raise MeshlabSharpError(f"run as root to add {_DEB_SRC} (a deb-src entry)")
    say(f"adding the deb-src entry {_DEB_SRC} (--allow-deb-src) and running apt-get update")
    _DEB_SRC.write_text(entry)
    _apt(["update", "-qq"])


def build(source: Path, build_dir: Path, sources: Path) -> Path:
    """Configure and build the plugin with CMake; return the built library.

    ``source``: the unpacked MeshLab source package (headers); ``sources``: the plugin's
    sources (:func:`plugin_sources`)."""
    build_dir.mkdir(parents=True, exist_ok=True)
    say(f"configuring the build with CMake in {build_dir}")
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
    say("compiling (a minute or two the first time)")
    started = time.monotonic()
    _check_call(["cmake", "--build", str(build_dir), "-j", str(min(os.cpu_count() or 1, 2))])
    say(f"compiled in {time.monotonic() - started:.0f} s")
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


def uninstall_system() -> list[Path]:
    """Remove the plugin from Debian's MeshLab plugin folder and the deb-src entry that
    ``--allow-deb-src`` added (then ``apt-get update``); returns what was removed."""
    removed = []
    for path in (SYSTEM_LIB / "plugins" / PLUGIN_FILE, _DEB_SRC):
        if path.exists():
            if not os.access(path.parent, os.W_OK):
                raise MeshlabSharpError(f"cannot remove {path}: run as root")
            path.unlink()
            removed.append(path)
    if _DEB_SRC in removed:
        say("apt-get update (the deb-src entry is gone)")
        _apt(["update", "-qq"])
    return removed


def remove_private_root(root: Path) -> list[Path]:
    """Remove what :func:`make_private_root` made at ``root`` (the copied binaries, the
    links, our plugin, then the folders left empty); returns the files removed.

    Raises
    ------
    MeshlabSharpError
        ``root`` is not a private MeshLab root (no plugin in it): nothing is removed.
    """
    root = root.resolve()
    bindir = root / "bin"
    libdir = root / "lib" / "x86_64-linux-gnu" / "meshlab"
    plugins = libdir / "plugins"
    if not (plugins / PLUGIN_FILE).is_file():
        raise MeshlabSharpError(
            f"{root}: not a private MeshLab root made by plugin install (no "
            f"{plugins.relative_to(root) / PLUGIN_FILE}); nothing removed"
        )
    ours = [bindir / "meshlab", bindir / "meshlabserver", plugins / PLUGIN_FILE]
    ours += [p for p in [libdir / "libmeshlab-common.so", *plugins.glob("*.so")] if p.is_symlink()]
    removed = []
    for path in ours:
        if path.is_symlink() or path.is_file():
            path.unlink()
            removed.append(path)
    for folder in (plugins, libdir, libdir.parent, libdir.parent.parent, bindir, root):
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
    return removed


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
