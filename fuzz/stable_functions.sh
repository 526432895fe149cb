# Sourced by fuzz/stable_edges.sh and fuzz/edge_diff.sh (after libfuzzer_flags.sh, from fuzz/):
# the fuzz binary of target $1 (BIN=FILE picks another build, e.g. a copy of the binary a run
# used; default: the default build fuzz/run.sh made last), and the functions whose edges the
# hash seed decides: serde-saphyr's duplicate-key maps under std's randomly seeded hasher, and
# KeyFingerprint::eq (stable_edges.sh says why). Always a sanitizer build: -print_coverage names
# the covered functions with the sanitizer runtime's symbolizer, and a SANITIZER=none build
# has none, so it would print no function and count 0. Also the suite's own crates
# ($our_crates, a regex of their names), which the scripts use to split the edges of our code
# from the dependencies'.
bin=${BIN:-$default_bin_dir/$1}
[ -x "$bin" ] || { echo "$bin missing: build it with fuzz/run.sh 0 $1" >&2; exit 2; }
nm "$bin" | grep ' T __sanitizer_symbolize_pc' >/dev/null || {
  echo "$bin has no sanitizer runtime to name covered functions (a SANITIZER=none build?):" \
    "use the default build, fuzz/run.sh 0 $1" >&2
  exit 2
}
hash_seeded='hashbrown::(map::HashMap|raw::RawTable)<\(?(serde_saphyr::de::key_nodes::KeyFingerprint|usize), \(\)|KeyFingerprint as core::cmp::PartialEq>::eq'
# The suite's crates, from their manifests (a dash in a package name is an underscore in a path).
our_crates="^($(awk -F'"' '/^name = / { gsub("-", "_", $2); printf "%s%s", sep, $2; sep = "|"
  nextfile }' ../msgs/Cargo.toml ../libs/*/Cargo.toml ../nodes/*/Cargo.toml ../tools/*/Cargo.toml \
  Cargo.toml))\$"
