//! The `therapist` console refuses a level outside 1..3 before sending anything, and says so
//! when no game manager answers, instead of waiting for ever. The second joins DDS, so the
//! test runs inside a loopback-only network namespace (tests/loopback-netns).

use std::time::Duration;

#[test]
fn a_bad_level_or_an_absent_game_manager_is_named() {
    let bin = env!("CARGO_BIN_EXE_therapist");
    let script = format!(
        "export RUST_BACKTRACE=0 RUST_LIB_BACKTRACE=0
         {bin} --params-file params/therapist_console.yaml override --session s1 --level 4
         echo \"exit=$?\"
         {bin} --params-file params/therapist_console.yaml start --user child-1 --cluster 0 --wait 2
         echo \"exit=$?\""
    );
    let Some(out) = loopback_netns::run_in_loopback_netns(&script, Duration::from_secs(60)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    // clap's usage error for the level, then our own for the missing game manager.
    assert!(stdout.contains("exit=2\n"), "{context}");
    assert!(
        stderr.contains("invalid value '4' for '--level <LEVEL>'") && stderr.contains("1..=3"),
        "{context}"
    );
    assert!(stdout.contains("exit=1\n"), "{context}");
    assert!(
        stderr.contains("no game manager published /qt_therapy/game/state within 2 s"),
        "{context}"
    );
    assert!(!stderr.contains("Cannot remove"), "{context}");
}
