#!/usr/bin/env bash
# Builds MuJoCo 2.2.2 from Debian's source package against glibc 2.28, for the manylinux_2_28
# wheel (python/build_wheel.sh). Debian's binary libmujoco.so.2.2.2 needs glibc 2.34
# (GLIBC_2.29 and GLIBC_2.34 symbol versions), which RHEL 8, Rocky 8 and Ubuntu 20.04 lack.
#
# The sources are Debian bookworm's: the upstream tarball of MuJoCo 2.2.2 (the same release as
# libmujoco-dev) and of the libraries libmujoco links (libccd, lodepng, qhull, tinyxml2,
# tinyobjloader, at the versions MuJoCo 2.2.2 pins), downloaded with `apt-get source` from
# bookworm's signed Sources index into a private apt state (nothing on the system changes).
# MuJoCo's own CMake builds them, with FetchContent pointed at the unpacked sources instead of
# GitHub, and links them statically into libmujoco.so.2.2.2 as upstream does.
#
# The compiler is zig (PyPI's `ziglang`), targeting x86_64-linux-gnu.2.28: it links against
# glibc 2.28's symbol versions and LLVM's libc++ statically, so the library needs only glibc
# 2.28 and libgcc_s. Like Debian's build it uses no AVX or FMA (MUJOCO_ENABLE_AVX=OFF), so
# its arithmetic is the same: python/tests/test_wheel.py checks the wheel's trajectories
# against the system library's, bit for bit.
#
# Output: $out/lib/libmujoco.so.2.2.2 (+ libmujoco.so), $out/include/mujoco/*.h and
# $out/licenses/ (MuJoCo's and every linked library's licence), where
# out=target/mujoco-manylinux_2_28 (or $1). Reuses a finished build. Needs cmake, ninja-build,
# and .ci/venv with ziglang (bash .ci/setup).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
out=${1:-$root/target/mujoco-manylinux_2_28}
venv=${MJSKILL_WHEEL_VENV:-.ci/venv}
glibc=2.28
if [ -f "$out/lib/libmujoco.so.2.2.2" ] && [ -f "$out/include/mujoco/mujoco.h" ]; then
  echo "$out/lib/libmujoco.so.2.2.2 (already built)"
  exit 0
fi
for tool in cmake ninja; do
  command -v "$tool" >/dev/null || { echo "error: $tool is missing: run bash .ci/setup" >&2; exit 1; }
done
"$venv/bin/python" -c "import ziglang" 2>/dev/null || {
  echo "error: $venv has no ziglang: run bash .ci/setup" >&2
  exit 1
}
zig_py=$(cd "$venv" && pwd)/bin/python
work=$out.build
rm -rf "$work" "$out"
mkdir -p "$work/apt/lists/partial" "$work/apt/cache/archives/partial" "$work/apt/parts" "$work/src"

# Debian bookworm's source index, in a private apt state.
cat >"$work/apt/parts/bookworm-src.sources" <<'EOF'
Types: deb-src
URIs: http://deb.debian.org/debian
Suites: bookworm
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
apt_opts=(-o Dir::Etc::SourceList=/dev/null -o "Dir::Etc::SourceParts=$work/apt/parts"
  -o "Dir::State::Lists=$work/apt/lists" -o "Dir::Cache=$work/apt/cache"
  -o APT::Sandbox::User=root -qq)
apt-get "${apt_opts[@]}" update
# The upstream tarballs only (`--download-only`): apt checks each against the signed index.
# MuJoCo's Debian packaging (mujoco_2.2.2-3.debian.tar.xz) is not used: it switches the build
# to the system's shared libraries, which is what this build avoids.
cd "$work/src"
for pkg in mujoco=2.2.2-3 libccd lodepng qhull tinyxml2 tinyobjloader; do
  apt-get "${apt_opts[@]}" source --download-only "$pkg" >"$work/apt/$pkg.log" 2>&1 || true
done
unpack() { # name, tarball glob
  local tarball
  tarball=$(ls $2 2>/dev/null | head -n 1 || true)
  [ -n "$tarball" ] || {
    echo "error: the Debian source of $1 did not download; apt said:" >&2
    cat "$work"/apt/*.log >&2
    exit 1
  }
  mkdir "$1"
  tar xf "$tarball" -C "$1" --strip-components=1
}
unpack mujoco 'mujoco_2.2.2.orig.tar.*'
unpack ccd 'libccd_*.orig.tar.*'
unpack lodepng 'lodepng_*.orig.tar.*'
unpack qhull 'qhull_*.orig.tar.*'
unpack tinyxml2 'tinyxml2_*.orig.tar.*'
unpack tinyobjloader 'tinyobjloader_*.orig.tar.*'

# zig as the C and C++ compiler, for glibc 2.28 and the baseline x86-64 (no AVX, no FMA).
mkdir -p "$work/bin"
for lang in cc c++; do
  cat >"$work/bin/zig-$lang" <<WRAP
#!/bin/sh
exec "$zig_py" -m ziglang $lang -target x86_64-linux-gnu.$glibc -mcpu=x86_64 "\$@"
WRAP
  chmod +x "$work/bin/zig-$lang"
done

cmake -S "$work/src/mujoco" -B "$work/build" -G Ninja \
  -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_C_COMPILER="$work/bin/zig-cc" -DCMAKE_CXX_COMPILER="$work/bin/zig-c++" \
  -DCMAKE_INSTALL_PREFIX="$out" -DCMAKE_INSTALL_LIBDIR=lib \
  -DMUJOCO_ENABLE_AVX=OFF -DMUJOCO_ENABLE_AVX_INTRINSICS=OFF \
  -DMUJOCO_BUILD_EXAMPLES=OFF -DMUJOCO_BUILD_SIMULATE=OFF -DMUJOCO_BUILD_TESTS=OFF \
  -DMUJOCO_TEST_PYTHON_UTIL=OFF -DBUILD_TESTING=OFF -DLIBM_LIBRARY:STRING=-lm \
  -DFETCHCONTENT_FULLY_DISCONNECTED=ON \
  -DFETCHCONTENT_SOURCE_DIR_CCD="$work/src/ccd" \
  -DFETCHCONTENT_SOURCE_DIR_LODEPNG="$work/src/lodepng" \
  -DFETCHCONTENT_SOURCE_DIR_QHULL="$work/src/qhull" \
  -DFETCHCONTENT_SOURCE_DIR_TINYXML2="$work/src/tinyxml2" \
  -DFETCHCONTENT_SOURCE_DIR_TINYOBJLOADER="$work/src/tinyobjloader" >"$work/cmake.log" 2>&1 || {
  tail -n 30 "$work/cmake.log" >&2
  exit 1
}
ninja -C "$work/build" ${CMAKE_BUILD_PARALLEL_LEVEL:+-j "$CMAKE_BUILD_PARALLEL_LEVEL"} mujoco \
  >"$work/build.log" 2>&1 || { tail -n 30 "$work/build.log" >&2; exit 1; }
mkdir -p "$out/lib" "$out/include"
cp -P "$work/build/lib/"libmujoco.so* "$out/lib/"
# zig leaves DWARF in a release build (18 MB of the 19): the wheel ships without it.
strip --strip-debug "$out/lib/libmujoco.so.2.2.2"
cp -r "$work/src/mujoco/include/mujoco" "$out/include/"
# The licences of everything linked into the library: MuJoCo, the five libraries it builds in,
# and zig's runtime (LLVM's libc++, libc++abi and libunwind; zig's compiler_rt).
zig_lib=$("$zig_py" -c 'import os, ziglang; print(os.path.dirname(ziglang.__file__))')
mkdir -p "$out/licenses"
for pair in mujoco/LICENSE:MuJoCo-LICENSE ccd/BSD-LICENSE:libccd-LICENSE \
  lodepng/LICENSE:lodepng-LICENSE qhull/COPYING.txt:qhull-COPYING.txt \
  tinyxml2/LICENSE.txt:tinyxml2-LICENSE.txt tinyobjloader/LICENSE:tinyobjloader-LICENSE; do
  cp "$work/src/${pair%%:*}" "$out/licenses/${pair##*:}"
done
cp "$zig_lib/lib/libcxx/LICENSE.TXT" "$out/licenses/LLVM-libcxx-libcxxabi-libunwind-LICENSE.TXT"
cp "$zig_lib/LICENSE" "$out/licenses/zig-compiler_rt-LICENSE"

# Check: no glibc symbol version above 2.28, and no libstdc++.
lib=$out/lib/libmujoco.so.2.2.2
newest=$(objdump -T "$lib" | grep -o 'GLIBC_[0-9.]*' | sort -Vu | tail -n 1)
printf '%s\n%s\n' "$newest" "GLIBC_$glibc" | sort -VC || {
  echo "error: $lib needs $newest, newer than GLIBC_$glibc" >&2
  exit 1
}
if objdump -p "$lib" | grep -q 'NEEDED.*libstdc++'; then
  echo "error: $lib links libstdc++" >&2
  exit 1
fi
rm -rf "$work"
echo "$lib (newest symbol version $newest)"
