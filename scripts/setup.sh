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
# torch first and pinned, so no dependency can pull a CUDA build.
"$VENV/bin/pip" install -q --disable-pip-version-check torch==2.13.0 2>&1 | grep -v "^WARNING: Location" || true
"$VENV/bin/pip" install -q --disable-pip-version-check -c requirements.lock -e ".[all,test,docs]" 2>&1 | grep -v "^WARNING: Location" || true
"$VENV/bin/python" -c "import motorlab, torch; assert '+cpu' in torch.__version__ or not torch.cuda.is_available()" \
  || { echo "setup: motorlab did not install; see the pip output above" >&2; exit 1; }
touch "$VENV/.installed"
