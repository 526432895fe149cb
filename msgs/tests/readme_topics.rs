//! The README's topic table must list every topic and service of `topics.rs`, with its type.

use qt_therapy_msgs::topics::{ASSIGN_CLUSTER, DECIDE_ACTION, PREDICT_USER, all_topics};

#[test]
fn readme_lists_every_topic_and_service() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"))
        .expect("README.md");
    for t in all_topics() {
        // Our own types appear as `msg/Type` under the package heading, others in full.
        let short = if t.package == "qt_therapy_msgs" {
            format!("msg/{}", t.type_short_name)
        } else {
            format!("{}/{}", t.package, t.type_short_name)
        };
        let row = readme
            .lines()
            .find(|l| l.starts_with(&format!("| `{}` |", t.name)));
        let row = row.unwrap_or_else(|| panic!("README has no row for {}", t.name));
        assert!(
            row.contains(&format!("`{short}`")),
            "README row for {} does not name {short}: {row}",
            t.name
        );
    }
    for (name, ty) in [
        (PREDICT_USER.name, "srv/PredictUser"),
        (ASSIGN_CLUSTER.name, "srv/AssignCluster"),
        (DECIDE_ACTION.name, "srv/DecideAction"),
    ] {
        assert!(
            readme.contains(&format!("| `{name}` | `{ty}` |")),
            "README has no row for {name}"
        );
    }
}
