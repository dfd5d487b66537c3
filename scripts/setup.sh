#!/usr/bin/env bash
# Set up meshlab-sharp on Debian 12: system libraries, a virtual environment in .venv
# with the package installed (editable), and with --all also what the tests and the
# MeshLab plugin need (test extras, MeshLab 2020.09, its build dependencies, Xvfb).
#
#   bash scripts/setup.sh          # the Python package (with matplotlib for --plot)
#   bash scripts/setup.sh --all    # + test tools, MeshLab 2020.09 and the plugin's build needs
set -euo pipefail
cd "$(dirname "$0")/.."

all=0
[[ "${1:-}" == "--all" ]] && all=1

sudo=""
if [[ "$(id -u)" != 0 ]]; then sudo="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

# pymeshlab needs libgl1 (import) and libopengl0 (its PLY/OBJ/OFF/STL plugins).
packages=(libgl1 libopengl0 libgomp1 python3 python3-venv python3-pip python3-dev gcc g++)  # g++: the native library has C++ sources
if [[ $all == 1 ]]; then
  packages+=(xdotool imagemagick)  # the GUI test drives MeshLab and takes screenshots
  packages+=(libglu1-mesa libxcursor1 libxft2 libxinerama1)  # the gmsh wheel's library (cad extra)
fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if (( ${#missing[@]} )); then
  echo "setup: installing Debian packages: ${missing[*]}"
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

python=${PYTHON:-python3}
if [[ ! -x .venv/bin/python ]]; then
  "$python" -m venv .venv
fi
extras="[plot,dxf]"
[[ $all == 1 ]] && extras="[plot,dxf,test,las,e57,dask,docs,cad]"
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".${extras}"
if [[ $all == 1 ]]; then
  # MeshLab 2020.09, the plugin's build dependencies and its headers (Debian source package;
  # --allow-deb-src: apt's deb-src entry is added if missing, `plugin uninstall` removes it).
  .venv/bin/meshlab-sharp plugin deps --allow-deb-src
fi
echo "setup: ready: run .venv/bin/meshlab-sharp, or source .venv/bin/activate first for plain meshlab-sharp"
