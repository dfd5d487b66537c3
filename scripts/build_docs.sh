#!/usr/bin/env bash
# Build the documentation site (the guide in docs/ and the API reference generated from
# the docstrings) into site/, failing on any warning: a broken link or reference fails.
#
#   bash scripts/build_docs.sh            # needs the docs extra: pip install -e '.[docs]'
set -euo pipefail
cd "$(dirname "$0")/.."
python=${PYTHON:-.venv/bin/python}
[[ -x "$python" ]] || python=python3
"$python" -m mkdocs build --strict --site-dir site "$@"
echo "build_docs: site/index.html"
