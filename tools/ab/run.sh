#!/usr/bin/env bash
# Side-by-side A/B of CanopyBroadPhase: the working tree against git revision REV, in one
# process (tools/ab/main.rs says how it times). Builds REV's canopy-core and canopy-rapier
# under other package names in target/ab/old, and the harness in target/ab/bench.
#
#   tools/ab/run.sh REV SCENE[,SCENE...] STEPS [REPS]
#   BLOCK=1 ...   each broadphase's updates back to back (as criterion runs them)
#   RAPIER=1 ...  Rapier's BroadPhaseBvh too
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
rev="${1:?usage: tools/ab/run.sh REV SCENE[,SCENE...] STEPS [REPS]}"
shift
ab="$root/target/ab"
rm -rf "$ab/old" "$ab/bench"
mkdir -p "$ab/old" "$ab/bench/src"
git -C "$root" archive "$rev" crates/canopy-core crates/canopy-rapier | tar -x -C "$ab/old"
old="$ab/old/crates"
cat > "$old/canopy-core/Cargo.toml" <<TOML
[package]
name = "canopy-core-old"
version = "0.1.0"
edition = "2021"

[lib]
name = "canopy_core"
path = "src/lib.rs"

[dependencies]
nalgebra = "0.33"
rayon = "1.10"
thiserror = "2"
smallvec = "1.13"
TOML
cat > "$old/canopy-rapier/Cargo.toml" <<TOML
[package]
name = "canopy-rapier-old"
version = "0.1.0"
edition = "2021"

[lib]
name = "canopy_rapier_old"
path = "src/lib.rs"

[dependencies]
canopy_core = { package = "canopy-core-old", path = "../canopy-core" }
rapier3d = "=0.27.0"
rayon = "1.10"
rustc-hash = "2"
smallvec = "1.13"
thiserror = "2"
TOML
cat > "$ab/bench/Cargo.toml" <<TOML
[package]
name = "canopy-ab"
version = "0.1.0"
edition = "2021"

[dependencies]
canopy-rapier = { path = "$root/crates/canopy-rapier" }
canopy-scenes = { path = "$root/crates/canopy-scenes" }
canopy-rapier-old = { path = "$old/canopy-rapier" }
rapier3d = "=0.27.0"
rayon = "1.10"

[profile.release]
debug = 1

[workspace]
TOML
cp "$root/tools/ab/main.rs" "$ab/bench/src/main.rs"
cp "$root/Cargo.lock" "$ab/bench/Cargo.lock"
CARGO_TARGET_DIR="$ab/target" cargo build --release --manifest-path "$ab/bench/Cargo.toml"
"$ab/target/release/canopy-ab" "$@"
