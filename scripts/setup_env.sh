#!/usr/bin/env bash
# Create or reuse the project-local virtual environment .venv, install pinned dependencies,
# build awalker_msgs into it (only when a .msg or the build files changed) and install the
# two Python packages in editable mode. Idempotent: a re-run with nothing changed takes ~1 s.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
py="${PYTHON:-python3}"
stamp_dir="$venv/.awalker"

log() { printf '[setup] %s\n' "$*"; }

if [ ! -x "$venv/bin/python" ]; then
  log "creating $venv with $($py --version)"
  "$py" -m venv "$venv"
fi
mkdir -p "$stamp_dir"
vpy="$venv/bin/python"

req_hash=$(sha256sum "$root/requirements.txt" | cut -d' ' -f1)
if [ "$(cat "$stamp_dir/requirements.sha256" 2>/dev/null)" != "$req_hash" ]; then
  log "installing pinned dependencies (first run: ~1-2 min)"
  # --no-cache-dir: the downloaded wheels are not kept a second time in ~/.cache/pip (disk is tight on CI)
  "$vpy" -m pip install --disable-pip-version-check --no-cache-dir -q -r "$root/requirements.txt" 2>&1 \
    | { grep -v "^WARNING: Location .* is ignored" || true; }
  # The ROS wheels bake their builder's header paths into cmake files; point them at this venv.
  py_inc=$("$vpy" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
  np_inc=$("$vpy" -c 'import numpy; print(numpy.get_include())')
  { grep -rlE '/opt/python/cp3[0-9]+-cp3[0-9]+' "$venv/share" --include='*.cmake' 2>/dev/null || true; } \
    | xargs -r sed -i -E \
        -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#$np_inc#g" \
        -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#$py_inc#g"
  echo "$req_hash" > "$stamp_dir/requirements.sha256"
  rm -f "$stamp_dir/msgs.sha256"
fi

msgs_hash=$(cat "$root"/src/awalker_msgs/msg/*.msg "$root"/src/awalker_msgs/CMakeLists.txt \
  "$root"/src/awalker_msgs/package.xml | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp_dir/msgs.sha256" 2>/dev/null)" != "$msgs_hash" ]; then
  log "building awalker_msgs into the venv"
  build="$venv/build/awalker_msgs"
  rm -rf "$build"
  mkdir -p "$build"
  (
    export PATH="$venv/bin:$PATH" VIRTUAL_ENV="$venv"
    export AMENT_PREFIX_PATH="$venv" CMAKE_PREFIX_PATH="$venv"
    cmake -S "$root/src/awalker_msgs" -B "$build" -DCMAKE_PREFIX_PATH="$venv" \
      -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$vpy" -DBUILD_TESTING=OFF \
      -DCMAKE_BUILD_TYPE=Release > "$build/configure.log" 2>&1 \
      || { cat "$build/configure.log"; exit 1; }
    cmake --build "$build" -j "$(nproc)" > "$build/build.log" 2>&1 \
      || { tail -50 "$build/build.log"; exit 1; }
    cmake --install "$build" > "$build/install.log" 2>&1 || { cat "$build/install.log"; exit 1; }
  )
  echo "$msgs_hash" > "$stamp_dir/msgs.sha256"
fi

pkg_hash=$(cat "$root"/src/awalker_*/setup.* | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp_dir/packages.sha256" 2>/dev/null)" != "$pkg_hash" ]; then
  log "installing awalker_tracker and awalker_tools (editable)"
  "$vpy" -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation \
    -e "$root/src/awalker_tracker" -e "$root/src/awalker_tools"
  echo "$pkg_hash" > "$stamp_dir/packages.sha256"
fi
log "ready: $venv"
