import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(scope="session")
def meshlab_root(tmp_path_factory):
    """Build the plugin from scratch and install it into a private MeshLab root."""
    from meshlab_sharp import plugin
    from meshlab_sharp.cli import main

    missing = plugin.missing_packages()
    if missing:
        pytest.fail(f"missing Debian packages {missing}: run bash scripts/setup.sh --all")
    base = tmp_path_factory.mktemp("meshlab")
    root, build = base / "root", base / "build"
    code = main(["plugin", "install", "--root", str(root), "--build-dir", str(build), "--no-apt"])
    assert code == 0
    assert (build / plugin.PLUGIN_FILE).is_file()
    return root
