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

/// `--check` says what is wrong without joining DDS: the package's empty PIN until
/// QT_TABLET_PIN sets one, a ROS_DOMAIN_ID out of range, an address other computers reach
/// without a certificate, a certificate or key it cannot load; and passes a setting it can run
/// with (the installed one: every address, the robot's own certificate).
#[test]
fn check_names_a_missing_pin_and_a_bad_domain_and_passes_a_good_setting() {
    let bin = env!("CARGO_BIN_EXE_tablet_bridge");
    let dir = tempfile::tempdir().expect("temp dir");
    let tls = dir.path().join("tls");
    let made = std::process::Command::new(env!("CARGO_BIN_EXE_tablet_tls"))
        .arg("--dir")
        .arg(&tls)
        .args(["init", "--only-names", "--name", "qtrobot.test"])
        .output()
        .expect("tablet_tls runs");
    assert!(made.status.success(), "{made:?}");
    let file = dir.path().join("tablet_bridge.yaml");
    let write = |tls_lines: &str| {
        std::fs::write(
            &file,
            format!(
                "tablet_bridge:\n  ros__parameters:\n    http_bind: \"0.0.0.0:8080\"\n    pin: \"\"\n{tls_lines}"
            ),
        )
        .expect("writes the parameter file")
    };
    let installed = format!(
        "    tls_cert_file: \"{0}/server.crt\"\n    tls_key_file: \"{0}/server.key\"\n",
        tls.display()
    );
    write(&installed);
    let check = |pin: Option<&str>, domain: &str| {
        let mut c = std::process::Command::new(bin);
        c.args(["--check", "--params-file"])
            .arg(&file)
            .env("ROS_DOMAIN_ID", domain)
            .env("RUST_BACKTRACE", "0")
            .env("RUST_LIB_BACKTRACE", "0")
            .env_remove("QT_TABLET_PIN");
        if let Some(pin) = pin {
            c.env("QT_TABLET_PIN", pin);
        }
        let out = c.output().expect("runs");
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned()
                + &String::from_utf8_lossy(&out.stderr),
        )
    };
    let (ok, out) = check(None, "0");
    assert!(
        !ok && out.contains("pin") && out.contains("QT_TABLET_PIN"),
        "{out}"
    );
    let (ok, out) = check(Some("12"), "0");
    assert!(!ok && out.contains("at least 4 characters"), "{out}");
    let (ok, out) = check(Some("8642"), "300");
    assert!(!ok && out.contains("ROS_DOMAIN_ID"), "{out}");
    let (ok, out) = check(Some("8642"), "7");
    assert!(
        ok && out.contains("parameters and environment valid"),
        "{out}"
    );
    // Every address, no certificate: refused, saying how to go on.
    write("");
    let (ok, out) = check(Some("8642"), "7");
    assert!(
        !ok && out.contains("tls_cert_file") && out.contains("allow_plain_http: true"),
        "{out}"
    );
    write("    allow_plain_http: true\n");
    let (ok, out) = check(Some("8642"), "7");
    assert!(ok, "{out}");
    // A key that is not there (a clinic's path mistyped), or not the certificate's.
    write(&installed.replace("server.key", "clinic.key"));
    let (ok, out) = check(Some("8642"), "7");
    assert!(
        !ok && out.contains("tls_key_file") && out.contains("clinic.key"),
        "{out}"
    );
    write(&installed.replace("server.key", "ca.key"));
    let (ok, out) = check(Some("8642"), "7");
    assert!(
        !ok && out.contains("is not the key of the certificate"),
        "{out}"
    );
}
