//! The `simulated_child` binary refuses what it cannot play and says why: a parameter it does
//! not have (named with its file, before joining DDS) and a cluster its user-model file does
//! not hold (named with the file). It joins DDS for the second, so the test runs inside a
//! loopback-only network namespace (tests/loopback-netns).

use std::time::Duration;

#[test]
fn a_wrong_parameter_or_cluster_is_named_and_the_child_exits() {
    let bin = env!("CARGO_BIN_EXE_simulated_child");
    let script = format!(
        "export RUST_BACKTRACE=0 RUST_LIB_BACKTRACE=0
         {bin} --params-file params/simulated_child.yaml --param no_such_key:=1; echo \"exit=$?\"
         {bin} --params-file params/simulated_child.yaml --cluster 9; echo \"exit=$?\""
    );
    let Some(out) = loopback_netns::run_in_loopback_netns(&script, Duration::from_secs(60)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_eq!(stdout.matches("exit=1").count(), 2, "{context}");
    assert!(
        stderr.contains("params/simulated_child.yaml")
            && stderr.contains("unknown field `no_such_key`"),
        "{context}"
    );
    let model = "nodes/user_model/models/migrave_study_c2.json";
    assert!(
        stderr.contains(&format!("Error: user_model_file {model}"))
            && stderr.contains("cluster 9 does not exist (the model has 2)"),
        "{context}"
    );
    // The shell was stopped before the error: RustDDS had nothing left to complain about.
    assert!(!stderr.contains("Cannot remove"), "{context}");
}
