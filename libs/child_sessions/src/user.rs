//! The user id an export or erase is for, and whether a free text (a log line, a report) names
//! it. Structured files (session files, bags, CSV rows, Q-tables) are matched on their user
//! field exactly; free text only where the id stands as a whole token, so erasing user `7`
//! does not take every log line holding a 7, nor user `child-7` the lines of `child-7-2`.

use crate::error::StoredError;
use qt_therapy_msgs::validate::MAX_ID_LEN;

/// A user id as the therapist gave it at START (`TherapistCommand.user_id`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UserId {
    id: String,
    /// The id as free text may hold it: as written, as Rust's `{:?}` escapes it (the game
    /// manager logs `started for user "…"`), as HTML escapes it (the session report).
    forms: Vec<String>,
}

impl UserId {
    /// The id, checked as the game manager checks it: no session can have another.
    pub fn new(id: &str) -> Result<UserId, StoredError> {
        let bad = |reason: &str| StoredError::UserId {
            id: id.chars().take(140).collect(),
            reason: reason.to_string(),
        };
        if id.trim().is_empty() {
            return Err(bad("is empty"));
        }
        if id.len() > MAX_ID_LEN {
            return Err(bad(&format!(
                "is longer than {MAX_ID_LEN} bytes, which no session's user id can be"
            )));
        }
        if id.chars().any(char::is_control) {
            return Err(bad(
                "has control characters, which no session's user id can have",
            ));
        }
        let mut forms = vec![id.to_string()];
        let debug = format!("{id:?}");
        let debug = debug[1..debug.len() - 1].to_string();
        let html = html_escape(id);
        for form in [debug, html] {
            if !forms.contains(&form) {
                forms.push(form);
            }
        }
        Ok(UserId {
            id: id.to_string(),
            forms,
        })
    }

    pub fn as_str(&self) -> &str {
        &self.id
    }

    /// The id for a file name: anything but letters, digits, '-', '_' and '.' becomes '_'.
    pub fn file_stem(&self) -> String {
        sequence_game::id_file_stem(&self.id)
    }

    /// Whether `text` names this user as a whole token, in any of its written forms.
    pub fn named_in(&self, text: &str) -> bool {
        self.forms.iter().any(|f| names_token(text, f))
    }
}

/// `&`, `<`, `>`, `"`, `'` as the session report escapes them.
fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

/// Characters that continue an id: `child-7` inside `child-7-2` or `xchild-7` is another id.
fn is_id_char(c: char) -> bool {
    c.is_alphanumeric() || c == '-' || c == '_'
}

/// Whether `token` occurs in `text` with no id character glued to either side of it (where
/// the token itself begins or ends with one). The per-user Q-table's name, `user_<id>.json`,
/// counts as naming the id.
pub fn names_token(text: &str, token: &str) -> bool {
    if token.is_empty() {
        return false;
    }
    let starts = token.chars().next().is_some_and(is_id_char);
    let ends = token.chars().next_back().is_some_and(is_id_char);
    let mut from = 0;
    while let Some(i) = text[from..].find(token) {
        let start = from + i;
        let end = start + token.len();
        let mut before = text[..start].chars().rev();
        let mut after = text[end..].chars();
        let (b1, b2) = (before.next(), before.next());
        let (a1, a2) = (after.next(), after.next());
        // A '.' between digits glues a number together: `7` is not named in `7.5` or `0.7`.
        let decimal = |dot: Option<char>, digit: Option<char>| {
            dot == Some('.') && digit.is_some_and(|c| c.is_ascii_digit())
        };
        let before_ok = !starts
            || (b1.is_none_or(|c| !is_id_char(c)) && !decimal(b1, b2))
            || text[..start].ends_with("user_");
        let after_ok = !ends || (a1.is_none_or(|c| !is_id_char(c)) && !decimal(a1, a2));
        if before_ok && after_ok {
            return true;
        }
        from = start + text[start..].chars().next().map_or(1, char::len_utf8);
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_checked_as_the_game_manager_checks_them() {
        assert!(UserId::new("").is_err());
        assert!(UserId::new("   ").is_err());
        assert!(UserId::new("a\nb").is_err());
        assert!(UserId::new(&"x".repeat(129)).is_err());
        assert!(UserId::new(&"x".repeat(128)).is_ok());
        let e = UserId::new("a\tb").expect_err("control").to_string();
        assert!(e.contains("control characters"), "{e}");
    }

    #[test]
    fn free_text_names_an_id_only_as_a_whole_token() {
        let u = UserId::new("child-7").expect("valid");
        assert!(u.named_in(r#"session "s1" started for user "child-7" (cluster 0)"#));
        assert!(u.named_in("child-7"));
        assert!(u.named_in("saved q_tables/user_child-7.json"));
        assert!(u.named_in("user child-7's own table"));
        assert!(!u.named_in("user child-7-2 started"));
        assert!(!u.named_in("xchild-7"));
        assert!(!u.named_in("child-70"));
        let seven = UserId::new("7").expect("valid");
        assert!(!seven.named_in("sequence 17 of 70, 7.5 s, 0.7"));
        assert!(seven.named_in("q_tables/user_7.json"));
        assert!(seven.named_in("user 7."));
        // Escaped as the game manager's {:?} and the report's HTML write it.
        let quoted = UserId::new(r#"a"b"#).expect("valid");
        assert!(quoted.named_in(r#"started for user "a\"b" (cluster 1)"#));
        assert!(quoted.named_in("<title>Session s — user a&quot;b</title>"));
        assert_eq!(UserId::new("../a b").expect("valid").file_stem(), "_a_b");
    }
}
