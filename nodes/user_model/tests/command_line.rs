//! The `user_model` binary from the shell: simulate-study, fit (optimised and fixed
//! hyperparameters), predict; a failing fit writes nothing.

use std::process::Command;

fn user_model(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_user_model"))
        .args(args)
        .output()
        .expect("runs user_model")
}

#[test]
fn simulate_fit_predict() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("study.csv");
    let model = dir.path().join("m.json");
    let out = user_model(&[
        "simulate-study",
        "--output",
        data.to_str().expect("path"),
        "--seed",
        "3",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("SYNTHETIC"));
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--clusters",
        "2",
        "--seed",
        "5",
        "--output",
        model.to_str().expect("path"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for f in [
        "m.json",
        "clusters.svg",
        "clusters.png",
        "levels.svg",
        "levels.png",
    ] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
    let out = user_model(&["predict", "--model", model.to_str().expect("path")]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 1 + 2 * 126);
    assert!(lines[0].starts_with("cluster,level,feedback,previous_score,outcome,p_success"));
    for line in &lines[1..] {
        let cells: Vec<f64> = line
            .split(',')
            .map(|c| c.parse().expect("number"))
            .collect();
        assert_eq!(cells.len(), 9);
        assert!((0.0..=1.0).contains(&cells[5]) && cells[6] >= 0.0);
        assert!((-1.0..=1.0).contains(&cells[7]) && cells[8] >= 0.0);
    }
    // Fixed hyperparameters are kept as given.
    let fixed = dir.path().join("fixed.json");
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--fixed",
        "--length-scale",
        "0.5",
        "--alpha",
        "2",
        "--output",
        fixed.to_str().expect("path"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let set = user_model::UserModelSet::load(&fixed).expect("loads");
    for c in &set.file().clusters {
        assert_eq!(
            c.success.kernel,
            user_model::Kernel::RationalQuadratic {
                length_scale: 0.5,
                alpha: 2.0
            }
        );
    }
}

#[test]
fn a_failing_fit_writes_nothing_and_names_the_problem() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("study.csv");
    let model = dir.path().join("m.json");
    assert!(
        user_model(&["simulate-study", "--output", data.to_str().expect("path")])
            .status
            .success()
    );
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--clusters",
        "11",
        "--output",
        model.to_str().expect("path"),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("20 users cannot make 11 clusters"), "{err}");
    let text = std::fs::read_to_string(&data).expect("reads");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut cells: Vec<&str> = lines[1].split(',').collect();
    cells[3] = "8";
    lines[1] = cells.join(",");
    std::fs::write(&data, lines.join("\n")).expect("writes");
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--output",
        model.to_str().expect("path"),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("record 1, field level"), "{err}");
    let names: Vec<_> = std::fs::read_dir(dir.path()).expect("lists").collect();
    assert_eq!(names.len(), 1, "only the data file: {names:?}");
}
