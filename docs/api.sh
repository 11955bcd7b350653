#!/usr/bin/env bash
# Build the API reference (HTML, from the docstrings) with pdoc: pip install -e ".[docs]", then
#   docs/api.sh [OUT]          (default OUT: /tmp/qpcontact-api; open OUT/index.html)
# Every module is named, since the packages' __all__ would hide their submodules from pdoc.
# The generated HTML is not committed.
set -euo pipefail
out="${1:-/tmp/qpcontact-api}"
modules=$(python -c "import pkgutil, qpcontact; print(*(m.name for m in pkgutil.walk_packages(qpcontact.__path__, 'qpcontact.') if m.name != 'qpcontact.__main__'))")
# (pdoc warns when a module named here was already reached through its package: not a problem.)
# shellcheck disable=SC2086
python -m pdoc --docformat restructuredtext --output-directory "$out" qpcontact $modules \
    2> >(grep -v "already been added" >&2)
echo "API reference in $out/index.html"
