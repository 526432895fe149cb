//! Core tests of the child list and the progress: who may ask, a new code checked by the
//! rules of a user id, and a start that names only the child.

use super::*;
use crate::io::StoredRead;
use child_sessions::UserId;

fn request(kind: &str, pin: &str, user: Option<&str>) -> String {
    let mut v = json!({"type": kind, "pin": pin});
    if let Some(u) = user {
        v["user_id"] = json!(u);
    }
    v.to_string()
}

/// What the core asked the shell to read for page `id`.
fn reads(out: &[Output], id: ClientId) -> Vec<StoredRead> {
    out.iter()
        .filter_map(|o| match o {
            Output::Read(to, r) if *to == id => Some(r.clone()),
            _ => None,
        })
        .collect()
}

#[test]
fn only_a_logged_in_therapist_page_with_the_pin_may_read_the_children() {
    let mut b = Bridge::new(params(), at(0));
    let stranger = b.connect(Role::Therapist, at(0)).expect("room").0;
    let out = b.ws_text(stranger, &request("children", PIN, None), at(0));
    assert_eq!(reasons(&out, stranger), ["log in with the PIN first"]);
    assert!(reads(&out, stranger).is_empty());
    let c = child(&mut b);
    let out = b.ws_text(c, &request("progress", PIN, Some("child-7")), at(0));
    assert_eq!(
        reasons(&out, c),
        ["the child page cannot send requests for children's data"]
    );
    assert!(reads(&out, c).is_empty());

    let t = therapist(&mut b);
    let out = b.ws_text(t, &request("children", "0000", None), at(0));
    assert_eq!(reasons(&out, t), ["wrong PIN"]);
    let out = b.ws_text(t, &request("children", PIN, None), at(0));
    assert_eq!(reads(&out, t), [StoredRead::Children]);
    let out = b.ws_text(t, &request("progress", PIN, Some("child-7")), at(0));
    let user = UserId::new("child-7").expect("id");
    assert_eq!(reads(&out, t), [StoredRead::Progress(user)]);
}

#[test]
fn a_new_code_is_checked_as_a_user_id_is() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    let out = b.ws_text(t, &request("new_child", PIN, Some("child-9")), at(0));
    assert_eq!(
        to(&out, t),
        [ServerMessage::ChildChecked {
            user_id: "child-9".into()
        }]
    );
    let long = "x".repeat(129);
    for (code, reason) in [
        ("", "is empty"),
        ("   ", "is empty"),
        ("a\tb", "control characters"),
        (long.as_str(), "longer than 128 bytes"),
    ] {
        for kind in ["new_child", "progress"] {
            let out = b.ws_text(t, &request(kind, PIN, Some(code)), at(0));
            let got = reasons(&out, t);
            assert!(
                got.len() == 1 && got[0].contains(reason),
                "{kind} {code:?}: {got:?}"
            );
            assert!(reads(&out, t).is_empty());
        }
    }
}

#[test]
fn a_start_names_the_child_and_the_policy_takes_its_default_cluster() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    let out = b.ws_text(t, &cmd(PIN, "start", json!({"user_id": "child-9"})), at(5));
    let (commands, _) = published(&out);
    assert_eq!(commands.len(), 1, "{out:?}");
    assert_eq!(
        (commands[0].user_id.as_str(), commands[0].user_model_cluster),
        ("child-9", -1)
    );
}
