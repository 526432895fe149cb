//! Our PCA, K-means and GP agree with scikit-learn's on fixed data (fixture made once by
//! tests/fixtures/make_sklearn_fixture.py): PCA projection up to sign, the same partition, GP
//! mean/std, log marginal likelihood and its gradient to 1e-6 for every kernel, and the
//! optimised hyperparameters of the authors' setting.

use serde_json::Value;
use user_models::clustering::{Pca, kmeans};
use user_models::gp::{GaussianProcess, Kernel, OptimiserOptions};
use user_models::model::GpComponent;

fn fixture() -> Value {
    serde_json::from_str(include_str!("fixtures/sklearn_reference.json")).expect("fixture JSON")
}

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    serde_json::from_value(v.clone()).expect("matrix of numbers")
}

fn vector(v: &Value) -> Vec<f64> {
    serde_json::from_value(v.clone()).expect("vector of numbers")
}

fn close(what: &str, ours: f64, theirs: f64, tolerance: f64) {
    assert!(
        (ours - theirs).abs() <= tolerance,
        "{what}: ours {ours} vs scikit-learn {theirs} (|d| = {:e})",
        (ours - theirs).abs()
    );
}

#[test]
fn pca_projection_matches_up_to_sign() {
    let f = fixture();
    let users = matrix(&f["users"]);
    let pca = Pca::fit(&users, 2);
    let theirs = matrix(&f["pca_projection"]);
    for (c, variance) in vector(&f["pca_explained_variance"]).iter().enumerate() {
        close(
            "explained variance",
            pca.explained_variance[c],
            *variance,
            1e-9,
        );
        let sign = if pca.project(&users[0])[c] * theirs[0][c] < 0.0 {
            -1.0
        } else {
            1.0
        };
        for (u, t) in users.iter().zip(&theirs) {
            close("projection", sign * pca.project(u)[c], t[c], 1e-6);
        }
    }
}

#[test]
fn kmeans_gives_the_same_partition_and_inertia() {
    let f = fixture();
    let projected = matrix(&f["pca_projection"]);
    let km = kmeans(&projected, 2, 10, 7);
    let expected: Vec<usize> = serde_json::from_value(f["kmeans_labels"].clone()).expect("labels");
    // The same partition, whatever the cluster numbers.
    let same = km.labels == expected || km.labels.iter().zip(&expected).all(|(a, b)| a != b);
    assert!(same, "{:?} vs {expected:?}", km.labels);
    close(
        "inertia",
        km.inertia,
        f["kmeans_inertia"].as_f64().expect("inertia"),
        1e-9,
    );
}

#[test]
fn gp_mean_std_likelihood_and_gradient_match_at_fixed_hyperparameters() {
    let f = fixture();
    let x = matrix(&f["gp_X"]);
    let y = vector(&f["gp_y"]);
    let noise = f["gp_noise"].as_f64().expect("noise");
    let query = matrix(&f["gp_query"]);
    let cases = f["gp_cases"].as_array().expect("cases");
    assert_eq!(cases.len(), 5);
    for case in cases {
        let name = case["name"].as_str().expect("name");
        let kernel: Kernel = serde_json::from_value(case["kernel"].clone()).expect("kernel");
        let gp = GaussianProcess::fit(x.clone(), &y, kernel, noise).expect("fits");
        let lml = case["log_marginal_likelihood"].as_f64().expect("lml");
        close(
            &format!("{name} lml"),
            gp.log_marginal_likelihood(),
            lml,
            1e-6,
        );
        for (ours, theirs) in gp
            .log_marginal_likelihood_gradient()
            .iter()
            .zip(vector(&case["gradient"]))
        {
            close(&format!("{name} lml gradient"), *ours, theirs, 1e-6);
        }
        for ((q, m), s) in query
            .iter()
            .zip(vector(&case["mean"]))
            .zip(vector(&case["std"]))
        {
            let (om, os) = gp.predict(q).expect("predicts");
            close(&format!("{name} mean"), om, m, 1e-6);
            close(&format!("{name} std"), os, s, 1e-6);
        }
    }
}

fn rational_quadratic(kernel: Kernel) -> (f64, f64) {
    match kernel {
        Kernel::RationalQuadratic {
            length_scale,
            alpha,
        } => (length_scale, alpha),
        other => panic!("kernel kind changed to {other:?}"),
    }
}

#[test]
fn optimised_hyperparameters_match_sklearns() {
    let f = fixture();
    let gp = GaussianProcess::fit_optimised(
        matrix(&f["gp_X"]),
        &vector(&f["gp_y"]),
        Kernel::AUTHORS,
        1e-10,
        &OptimiserOptions::default(),
    )
    .expect("fits");
    let (l, a) = rational_quadratic(gp.kernel());
    close(
        "optimised lml",
        gp.log_marginal_likelihood(),
        f["opt_log_marginal_likelihood"].as_f64().expect("lml"),
        1e-6,
    );
    close(
        "length_scale",
        l,
        f["opt_length_scale"].as_f64().expect("l"),
        1e-5,
    );
    close("alpha", a, f["opt_alpha"].as_f64().expect("a"), 1e-6);
}

#[test]
fn the_authors_pipeline_on_encoded_inputs_matches() {
    let f = fixture();
    let c = GpComponent::fit(
        matrix(&f["pipeline_inputs"]),
        vector(&f["pipeline_targets"]),
        Kernel::AUTHORS,
        1e-10,
        Some(OptimiserOptions::default()),
    )
    .expect("fits");
    for (ours, theirs) in c.input_mean.iter().zip(vector(&f["pipeline_input_mean"])) {
        close("input mean", *ours, theirs, 1e-12);
    }
    for (ours, theirs) in c.input_scale.iter().zip(vector(&f["pipeline_input_scale"])) {
        close("input scale", *ours, theirs, 1e-12);
    }
    close(
        "pipeline lml",
        c.log_marginal_likelihood,
        f["pipeline_log_marginal_likelihood"].as_f64().expect("lml"),
        1e-6,
    );
    let (l, a) = rational_quadratic(c.kernel);
    close(
        "pipeline length_scale",
        l,
        f["pipeline_length_scale"].as_f64().expect("l"),
        1e-5,
    );
    close(
        "pipeline alpha",
        a,
        f["pipeline_alpha"].as_f64().expect("a"),
        1e-6,
    );
    let gp = c.build().expect("builds");
    for ((q, m), s) in matrix(&f["pipeline_query"])
        .iter()
        .zip(vector(&f["pipeline_mean"]))
        .zip(vector(&f["pipeline_std"]))
    {
        let (om, os) = gp.predict(&c.standardise(q)).expect("predicts");
        close("pipeline mean", om.clamp(0.0, 1.0), m, 1e-6);
        close("pipeline std", os, s, 1e-6);
    }
}
