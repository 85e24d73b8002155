#!/usr/bin/env bash
# One-time set-up behind `make demo` / `make test`: system libraries for offscreen
# rendering, a virtual environment under the repo, and the pinned Python packages.
# Re-running is cheap: each part checks what is already there.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}

# Debian packages: Mesa's EGL for offscreen rendering (MUJOCO_GL=egl) on a CPU, always;
# with --browser (make test), Chromium too, where the tests open the HTML reports.
packages=(libegl1 libegl-mesa0 libgl1-mesa-dri)
if [ "${1:-}" = "--browser" ]; then packages=(chromium); fi
missing=()
for pkg in "${packages[@]}"; do
  dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else SUDO="none"; fi
  if [ "$SUDO" = none ]; then
    echo "setup: missing Debian packages ${missing[*]}; install them as root." >&2
  else
    echo "setup: installing ${missing[*]}"
    $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
fi
if [ "${1:-}" = "--browser" ]; then
  command -v chromium >/dev/null || { echo "setup: chromium is missing (needed by the report tests)" >&2; exit 1; }
  touch "$VENV/.browser"
  exit 0
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "setup: creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
# The packages go in with uv (pinned here, into the venv from PyPI; several times faster than pip),
# from the same lock with the same extras, and with pip where uv cannot be installed.
UV_VERSION=0.13.9
pipq() { "$VENV/bin/pip" -q --disable-pip-version-check "$@" 2>&1 | grep -v "^WARNING: Location" || true; }
have_uv() { case "$("$VENV/bin/uv" --version 2>/dev/null)" in "uv $UV_VERSION "*) true ;; *) false ;; esac; }
have_uv || "$VENV/bin/pip" install -q --disable-pip-version-check "uv==$UV_VERSION" >/dev/null 2>&1 || true
have_uv || echo "setup: uv $UV_VERSION could not be installed; installing with pip instead (a few minutes)" >&2
# torch first, pinned and with pip: the CPU build is a local wheel that pip's configuration (find-links)
# points to; once it is installed, nothing below can pull a CUDA build. With uv, its dependencies come
# from uv (pinned by the lock) and its bytecode is compiled while uv downloads the rest. A re-run
# finds it installed and skips pip.
compiling=""
if ! "$VENV/bin/python" -c "import importlib.metadata as m, sys; sys.exit(m.version('torch') != '2.13.0+cpu')" 2>/dev/null; then
  if have_uv; then
    pipq install --no-deps --no-compile torch==2.13.0
    "$VENV/bin/python" -c "import compileall, importlib.metadata as m, sys
d = m.distribution('torch')
tops = sorted({f.parts[0] for f in d.files if f.suffix == '.py' and len(f.parts) > 1})
sys.exit(not all([compileall.compile_dir(d.locate_file(t), quiet=1, workers=0) for t in tops]))" >/dev/null 2>&1 &
    compiling=$!
  else
    pipq install torch==2.13.0
  fi
fi
installed=""
if have_uv; then
  # uv reads no pip configuration: hand it pip's indexes, find-links and certificates (files and PIP_*
  # variables, as `pip config list` shows them), so that it sees what pip sees
  pip_setting() {
    { "$VENV/bin/pip" config list 2>/dev/null || true; } \
      | sed -n "s/^[^.]*\.$1='\(.*\)'\$/\1/p" | sed 's/\\n/ /g' | tr ' ' '\n' | awk 'NF && !seen[$0]++'
  }
  uv_args=()
  while read -r url; do uv_args+=(--default-index "$url"); done < <(pip_setting index-url | sed -n 1p)
  while read -r dir; do uv_args+=(--find-links "$dir"); done < <(pip_setting find-links)
  while read -r url; do uv_args+=(--index "$url"); done < <(pip_setting extra-index-url)
  uv_args+=(--index-strategy unsafe-best-match)  # pip's rule: the best version across all indexes
  cert=$(pip_setting cert | sed -n 1p)
  if [ -n "$cert" ] && [ -z "${SSL_CERT_FILE:-}" ]; then export SSL_CERT_FILE="$cert"; fi
  # --compile-bytecode: the .pyc files now, on every core, as pip writes them (the studies start many
  # processes, and under PYTHONDONTWRITEBYTECODE=1 each would otherwise compile every module it imports)
  if "$VENV/bin/uv" pip install -q --python "$VENV/bin/python" "${uv_args[@]}" --compile-bytecode \
       -c requirements.lock -e ".[all,test,docs]"; then
    installed=uv
  else
    echo "setup: uv could not install the packages (above); trying pip" >&2
  fi
fi
if [ -n "$compiling" ]; then wait "$compiling" || true; fi
if [ -z "$installed" ]; then pipq install -c requirements.lock -e ".[all,test,docs]"; fi
"$VENV/bin/python" -c "import motorlab, torch; assert '+cpu' in torch.__version__ or not torch.cuda.is_available()" \
  || { echo "setup: motorlab did not install; see the output above" >&2; exit 1; }
touch "$VENV/.installed"
