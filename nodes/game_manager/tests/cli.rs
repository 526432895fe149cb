//! The `game_manager` binary refuses parameters it cannot run with and names the file it
//! read and the key: an unknown key, and a value out of range given on the command line. It
//! may join DDS before the second check, so the test runs inside a loopback-only network
//! namespace (tests/loopback-netns).

use std::time::Duration;

#[test]
fn a_wrong_parameter_is_named_with_its_file_and_the_node_exits() {
    let bin = env!("CARGO_BIN_EXE_game_manager");
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path().display();
    let script = format!(
        "export RUST_BACKTRACE=0 RUST_LIB_BACKTRACE=0
         {bin} run --sessions-dir {d}/a --params-file params/game_manager.yaml --param no_such_key:=1; echo \"exit=$?\"
         {bin} run --sessions-dir {d}/b --params-file params/game_manager.yaml --param sequences_per_session:=11; echo \"exit=$?\""
    );
    let Some(out) = loopback_netns::run_in_loopback_netns(&script, Duration::from_secs(60)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_eq!(stdout.matches("exit=1").count(), 2, "{context}");
    assert!(
        stderr.contains("params/game_manager.yaml")
            && stderr.contains("unknown field `no_such_key`"),
        "{context}"
    );
    assert!(
        stderr.contains("parameter file params/game_manager.yaml")
            && stderr.contains("sequences_per_session: must be in 1..=10"),
        "{context}"
    );
}
