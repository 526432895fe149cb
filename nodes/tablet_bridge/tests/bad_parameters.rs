//! The `tablet_bridge` binary refuses a parameter value it cannot run with and names the file
//! it actually read (`--params-file`), not the default one, and the key. It joins DDS before
//! it checks, so the test runs inside a loopback-only network namespace.

use std::time::Duration;

#[test]
fn a_bad_value_is_named_with_the_file_it_came_from() {
    let bin = env!("CARGO_BIN_EXE_tablet_bridge");
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("robot_bridge.yaml");
    std::fs::write(
        &file,
        "tablet_bridge:\n  ros__parameters:\n    http_bind: nowhere\n",
    )
    .expect("writes the parameter file");
    let script = format!(
        "export RUST_BACKTRACE=0 RUST_LIB_BACKTRACE=0
         {bin} --params-file {}; echo \"exit=$?\"",
        file.display()
    );
    let Some(out) = loopback_netns::run_in_loopback_netns(&script, Duration::from_secs(60)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(stdout.contains("exit=1"), "{context}");
    assert!(
        stderr.contains(&file.display().to_string())
            && stderr.contains("tablet_bridge parameter http_bind: \"nowhere\" is not ip:port"),
        "{context}"
    );
    assert!(!stderr.contains("params/tablet_bridge.yaml"), "{context}");
}
