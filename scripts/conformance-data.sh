#!/usr/bin/env bash
# The MCAP conformance suite's files (tests/conformance/data), from foxglove/mcap.
#
#   scripts/conformance-data.sh --check
#       Check the committed files against tests/conformance/SHA256SUMS (offline).
#   scripts/conformance-data.sh MCAP_GIT [REV]
#       Regenerate them from a foxglove/mcap git repository (a clone, a bare
#       mirror or a URL; REV defaults to HEAD) and replace tests/conformance/data.
#
# In foxglove/mcap the `.mcap` files are Git LFS objects (a plain clone or
# `git archive` gives 130-byte pointers), so they are regenerated with the
# repository's own generator (tests/conformance/scripts/generate-inputs.ts,
# with typescript/core as @mcap/core at the same revision; npm installs its few
# dependencies into a temporary directory). Every regenerated file must match
# its LFS pointer's sha256 and size, i.e. be the official file byte for byte;
# the `.json` expectations are plain git files and are copied as they are.
# Needs git, node >= 20 and npm (registry access).
set -euo pipefail

here=$(cd "$(dirname "$0")/.." && pwd)
dest="$here/tests/conformance"

if [[ "${1:-}" == "--check" ]]; then
    cd "$dest"
    sha256sum --check --quiet SHA256SUMS
    echo "conformance data: $(wc -l <SHA256SUMS) files match SHA256SUMS"
    exit 0
fi
if [[ $# -lt 1 ]]; then
    sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
fi

source=$1
rev=${2:-HEAD}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

if [[ -d "$source" ]]; then
    git_dir=$source
else
    git clone --bare --filter=blob:none --quiet "$source" "$work/mcap.git"
    git_dir=$work/mcap.git
fi
commit=$(git -C "$git_dir" rev-parse "$rev^{commit}")
echo "foxglove/mcap at $commit"

# The generator, its inputs and @mcap/core at that revision.
mkdir -p "$work/src"
git -C "$git_dir" archive "$commit" tests/conformance typescript/core | tar -x -C "$work/src"
cd "$work/src"
echo '{"name":"conformance-generate","private":true,"type":"module"}' >package.json
npm install --no-audit --no-fund --no-save --silent \
    @foxglove/crc@0.0.3 commander@11.1.0 tsx@4.23.5 heap-js@2.7.1 tslib@2.8.1
# @mcap/core from source (npm would remove it if installed before).
mkdir -p node_modules/@mcap
cp -r typescript/core node_modules/@mcap/core
node -e '
  const fs = require("fs");
  const file = "node_modules/@mcap/core/package.json";
  const p = JSON.parse(fs.readFileSync(file, "utf8"));
  p.main = "./src/index.ts";
  p.exports = { ".": "./src/index.ts" };
  fs.writeFileSync(file, JSON.stringify(p, null, 2));
'
ln -s ../../node_modules tests/conformance/node_modules
(cd tests/conformance && ../../node_modules/.bin/tsx scripts/generate-inputs.ts --data-dir "$work/out" >/dev/null)

# Byte for byte the official files: each must match its LFS pointer.
cd "$work/out"
: >"$work/SHA256SUMS"
count=0
while IFS= read -r file; do
    pointer=$(git -C "$git_dir" show "$commit:tests/conformance/data/${file#./}")
    oid=$(sed -n 's/^oid sha256://p' <<<"$pointer")
    size=$(sed -n 's/^size //p' <<<"$pointer")
    if [[ "$(sha256sum "$file" | cut -d' ' -f1)" != "$oid" || "$(stat -c %s "$file")" != "$size" ]]; then
        echo "error: $file does not match its LFS pointer (sha256 $oid, $size bytes)" >&2
        exit 1
    fi
    echo "$oid  data/${file#./}" >>"$work/SHA256SUMS"
    count=$((count + 1))
done < <(find . -name '*.mcap' | LC_ALL=C sort)

rm -rf "$dest/data"
mkdir -p "$dest"
cp -r "$work/src/tests/conformance/data" "$dest/data"
cp -r "$work/out/." "$dest/data/"
cp "$work/SHA256SUMS" "$dest/SHA256SUMS"
git -C "$git_dir" show "$commit:LICENSE" >"$dest/LICENSE-mcap.txt"
echo "$count files regenerated, identical to foxglove/mcap $commit; update the commit in tests/conformance/README.md"
