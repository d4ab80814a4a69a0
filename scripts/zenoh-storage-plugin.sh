#!/usr/bin/env bash
# Builds zenohd's storage manager plugin (libzenoh_plugin_storage_manager.so, the
# storages that keep glrmon's results for readers that were away:
# deploy/zenohd-history.json5) from crates.io and installs it beside zenohd, where
# zenohd looks for plugins first. A plugin must be built by the same compiler and
# against the same Zenoh release and dependencies as the zenohd that loads it: the
# crate is built with zenohd's own lock file.
#   usage: scripts/zenoh-storage-plugin.sh ZENOH_VERSION DEST_DIR
set -euo pipefail
version=$1
dest=$2
cargo=${CARGO:-cargo}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# A throw-away package whose one dependency brings the plugin's source into cargo's
# registry.
mkdir -p "$work/fetch/src"
cat > "$work/fetch/Cargo.toml" <<TOML
[package]
name = "fetch-zenoh-plugin"
version = "0.0.0"
edition = "2021"
publish = false
[dependencies]
zenoh-plugin-storage-manager = "=$version"
TOML
: > "$work/fetch/src/lib.rs"
(cd "$work/fetch" && "$cargo" fetch -q)
src=$(cd "$work/fetch" && "$cargo" metadata -q --format-version 1 \
  | python3 -c "import json,sys; d=json.load(sys.stdin); print([p['manifest_path'] for p in d['packages'] if p['name']=='zenoh-plugin-storage-manager'][0])")
cp -r "$(dirname "$src")" "$work/plugin"
registry=$(dirname "$(dirname "$src")")
# zenohd's lock file (its source is in the registry once `cargo install zenohd` ran).
if [ -f "$registry/zenohd-$version/Cargo.lock" ]; then
  cp "$registry/zenohd-$version/Cargo.lock" "$work/plugin/Cargo.lock"
else
  echo "zenohd $version's Cargo.lock is not in $registry: building with fresh dependencies" >&2
fi
(cd "$work/plugin" && CARGO_TARGET_DIR="$work/target" "$cargo" build -q --release)
mkdir -p "$dest"
cp "$work/target/release/libzenoh_plugin_storage_manager.so" "$dest/"
echo "zenohd storage plugin $version: $dest/libzenoh_plugin_storage_manager.so"
