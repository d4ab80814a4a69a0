#!/usr/bin/env bash
# Regenerates the generated blocks of docs/REPRODUCTION.md (`make reproduce`).
#
# Every block between a line
#   <!-- reproduce: COMMAND -->
# and the next line
#   <!-- /reproduce -->
# is replaced by COMMAND's standard output in a fenced block. COMMAND runs from the
# repository root, with the release builds of `glrmon` and of glrmon-cli's examples
# (`table1`) first on PATH. Only the blocks change: the prose around them is kept.
# A failing command stops the script and leaves the document as it was.
set -euo pipefail
cd "$(dirname "$0")/.."
doc=docs/REPRODUCTION.md
target=${CARGO_TARGET_DIR:-$PWD/target}
cargo build --release -q -p glrmon-cli --bin glrmon --examples
export PATH="$target/release:$target/release/examples:$PATH"
out=$(mktemp)
trap 'rm -f "$out"' EXIT
skipping=0
blocks=0
while IFS= read -r line || [[ -n $line ]]; do
    if [[ $skipping == 1 ]]; then
        if [[ $line == '<!-- /reproduce -->' ]]; then
            skipping=0
            printf '%s\n' "$line"
        fi
        continue
    fi
    printf '%s\n' "$line"
    if [[ $line =~ ^\<\!--\ reproduce:\ (.*)\ --\>$ ]]; then
        cmd=${BASH_REMATCH[1]}
        echo "reproduce: $cmd" >&2
        start=$SECONDS
        printf '```text\n$ %s\n' "$cmd"
        bash -c "$cmd"
        printf '```\n'
        echo "reproduce: $((SECONDS - start)) s" >&2
        skipping=1
        blocks=$((blocks + 1))
    fi
done <"$doc" >"$out"
if [[ $skipping == 1 ]]; then
    echo "reproduce: $doc: a block has no closing <!-- /reproduce --> line" >&2
    exit 1
fi
cp "$out" "$doc"
echo "reproduce: $blocks block(s) of $doc regenerated" >&2
