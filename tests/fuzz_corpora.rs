//! Replays the kept fuzz corpora and the inputs that once crashed (fuzz/corpus/TARGET and
//! fuzz/regressions/TARGET) through the fuzz targets' own bodies, included from
//! fuzz/src/lib.rs, so every input format stays panic-free without nightly or libFuzzer.

#[path = "../fuzz/src/lib.rs"]
mod suite_fuzz;

use std::path::{Path, PathBuf};

fn files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

#[test]
fn every_kept_fuzz_input_is_handled_without_panicking() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz");
    let mut failures = Vec::new();
    for (target, body) in suite_fuzz::TARGETS {
        let corpus = files(&root.join("corpus").join(target));
        assert!(
            !corpus.is_empty(),
            "fuzz/corpus/{target} is empty or missing: run fuzz/run.sh"
        );
        let regressions = files(&root.join("regressions").join(target));
        for file in corpus.iter().chain(&regressions) {
            let bytes = match std::fs::read(file) {
                Ok(bytes) => bytes,
                // A fuzzer running meanwhile replaces inputs with smaller ones: gone, not kept.
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
                Err(e) => panic!("{}: {e}", file.display()),
            };
            if let Err(panic) = std::panic::catch_unwind(|| body(&bytes)) {
                let why = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                failures.push(format!("{target}: {}: {why}", file.display()));
            }
        }
        println!(
            "{target}: {} corpus files, {} regressions replayed",
            corpus.len(),
            regressions.len()
        );
    }
    assert!(failures.is_empty(), "panics:\n{}", failures.join("\n"));
}
