//! Our PCA, K-means and GP agree with scikit-learn's on fixed data (fixture made once by
//! tests/fixtures/make_sklearn_fixture.py): projections up to sign, the same partition, GP
//! mean/std and log marginal likelihood to 1e-6, and the same optimised hyperparameters.

use serde_json::Value;
use user_model::clustering::{Pca, kmeans};
use user_model::gp::{GaussianProcess, Kernel};

fn fixture() -> Value {
    serde_json::from_str(include_str!("fixtures/sklearn_reference.json")).expect("fixture JSON")
}

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .expect("rows")
        .iter()
        .map(|r| {
            r.as_array()
                .expect("row")
                .iter()
                .map(|x| x.as_f64().expect("number"))
                .collect()
        })
        .collect()
}

fn vector(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("values")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

#[test]
fn pca_projection_matches_up_to_sign_and_kmeans_the_partition() {
    let f = fixture();
    let users = matrix(&f["users"]);
    let pca = Pca::fit(&users, 2);
    let ours: Vec<Vec<f64>> = users.iter().map(|u| pca.project(u)).collect();
    let theirs = matrix(&f["pca_projection"]);
    for c in 0..2 {
        let sign = if ours[0][c] * theirs[0][c] < 0.0 {
            -1.0
        } else {
            1.0
        };
        for (o, t) in ours.iter().zip(&theirs) {
            assert!(
                (sign * o[c] - t[c]).abs() < 1e-6,
                "component {c}: {} vs {}",
                o[c],
                t[c]
            );
        }
    }
    let labels = kmeans(&ours, 2, 10, 7).labels;
    let expected: Vec<usize> = vector(&f["kmeans_labels"])
        .iter()
        .map(|v| *v as usize)
        .collect();
    // The same partition, whatever the cluster numbers.
    let same = labels == expected || labels.iter().zip(&expected).all(|(a, b)| *a != *b);
    assert!(same, "{labels:?} vs {expected:?}");
}

#[test]
fn gp_mean_std_and_likelihood_match_at_fixed_hyperparameters() {
    let f = fixture();
    let x = matrix(&f["gp_X"]);
    let y = vector(&f["gp_y"]);
    let kernel = Kernel::RationalQuadratic {
        length_scale: f["gp_length_scale"].as_f64().expect("l"),
        alpha: f["gp_alpha"].as_f64().expect("a"),
    };
    let gp =
        GaussianProcess::fit(x, &y, kernel, f["gp_noise"].as_f64().expect("noise")).expect("fits");
    let lml = f["gp_log_marginal_likelihood"].as_f64().expect("lml");
    assert!(
        (gp.log_marginal_likelihood() - lml).abs() < 1e-6,
        "{} vs {lml}",
        gp.log_marginal_likelihood()
    );
    for ((q, m), s) in matrix(&f["gp_query"])
        .iter()
        .zip(vector(&f["gp_mean"]))
        .zip(vector(&f["gp_std"]))
    {
        let (om, os) = gp.predict(q).expect("predicts");
        assert!((om - m).abs() < 1e-6, "mean {om} vs {m}");
        assert!((os - s).abs() < 1e-6, "std {os} vs {s}");
    }
}

#[test]
fn optimised_hyperparameters_match_sklearns() {
    let f = fixture();
    let x = matrix(&f["gp_X"]);
    let y = vector(&f["gp_y"]);
    let gp = GaussianProcess::fit_optimised(
        x,
        &y,
        Kernel::RationalQuadratic {
            length_scale: 1.0,
            alpha: 1.5,
        },
        1e-10,
        (1e-5, 1e5),
        0,
        0,
    )
    .expect("fits");
    let lml = f["opt_log_marginal_likelihood"].as_f64().expect("lml");
    // Nelder-Mead and L-BFGS-B stop at slightly different points of the same optimum.
    assert!(
        (gp.log_marginal_likelihood() - lml).abs() < 1e-4,
        "{} vs {lml}",
        gp.log_marginal_likelihood()
    );
    let Kernel::RationalQuadratic {
        length_scale,
        alpha,
    } = gp.kernel()
    else {
        panic!("kernel kind changed")
    };
    let (l, a) = (
        f["opt_length_scale"].as_f64().expect("l"),
        f["opt_alpha"].as_f64().expect("a"),
    );
    assert!(
        (length_scale / l - 1.0).abs() < 1e-2 && (alpha / a - 1.0).abs() < 5e-2,
        "({length_scale}, {alpha}) vs ({l}, {a})"
    );
}
