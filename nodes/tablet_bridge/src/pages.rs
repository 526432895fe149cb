//! The tablets' pages, compiled into the binary: plain HTML, CSS, JavaScript and the four
//! emotion faces (SVG drawn for this project). Nothing is fetched from outside the bridge.

use std::collections::BTreeMap;

/// One file served at a fixed path.
#[derive(Debug, Clone)]
pub struct Asset {
    pub content_type: &'static str,
    pub body: String,
}

const HTML: &str = "text/html; charset=utf-8";
const CSS: &str = "text/css; charset=utf-8";
const JS: &str = "text/javascript; charset=utf-8";
const SVG: &str = "image/svg+xml";

/// (path, content type, body); HTML bodies have `{{lang}}` replaced by the page language.
const FILES: [(&str, &str, &str); 17] = [
    ("/", HTML, include_str!("../assets/index.html")),
    ("/child", HTML, include_str!("../assets/child.html")),
    ("/therapist", HTML, include_str!("../assets/therapist.html")),
    (
        "/assets/common.css",
        CSS,
        include_str!("../assets/common.css"),
    ),
    (
        "/assets/child.css",
        CSS,
        include_str!("../assets/child.css"),
    ),
    (
        "/assets/therapist.css",
        CSS,
        include_str!("../assets/therapist.css"),
    ),
    ("/assets/i18n.js", JS, include_str!("../assets/i18n.js")),
    ("/assets/socket.js", JS, include_str!("../assets/socket.js")),
    ("/assets/child.js", JS, include_str!("../assets/child.js")),
    (
        "/assets/therapist.js",
        JS,
        include_str!("../assets/therapist.js"),
    ),
    (
        "/assets/proposal.js",
        JS,
        include_str!("../assets/proposal.js"),
    ),
    (
        "/assets/children.js",
        JS,
        include_str!("../assets/children.js"),
    ),
    // A child's progress (the report's body inside the therapist page), styled as the report.
    (
        "/assets/progress.css",
        CSS,
        child_sessions::report::STYLESHEET,
    ),
    (
        "/assets/faces/happy.svg",
        SVG,
        include_str!("../assets/faces/happy.svg"),
    ),
    (
        "/assets/faces/disgusted.svg",
        SVG,
        include_str!("../assets/faces/disgusted.svg"),
    ),
    (
        "/assets/faces/sad.svg",
        SVG,
        include_str!("../assets/faces/sad.svg"),
    ),
    (
        "/assets/faces/angry.svg",
        SVG,
        include_str!("../assets/faces/angry.svg"),
    ),
];

/// Every page and asset, by path.
#[derive(Debug, Clone)]
pub struct Pages {
    files: BTreeMap<&'static str, Asset>,
}

impl Pages {
    /// The pages in `language` (already validated: `en` or `de`).
    pub fn new(language: &str) -> Self {
        let files = FILES
            .iter()
            .map(|(path, content_type, body)| {
                let body = if *content_type == HTML {
                    body.replace("{{lang}}", language)
                } else {
                    (*body).to_string()
                };
                (*path, Asset { content_type, body })
            })
            .collect();
        Pages { files }
    }

    pub fn get(&self, path: &str) -> Option<&Asset> {
        self.files.get(path)
    }

    pub fn paths(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.files.keys().copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pages_carry_the_language_and_load_nothing_from_outside() {
        let pages = Pages::new("de");
        for path in ["/", "/child", "/therapist"] {
            let page = pages.get(path).expect(path);
            assert!(page.body.contains(r#"<html lang="de">"#), "{path}");
        }
        for path in pages.paths() {
            let body = &pages.get(path).expect(path).body;
            // Only the SVG namespace URI may look like an address; it is never fetched.
            let stripped = body.replace("http://www.w3.org/2000/svg", "");
            for needle in ["http://", "https://", "//cdn", "@import", "url("] {
                assert!(!stripped.contains(needle), "{path} contains {needle}");
            }
        }
    }

    /// Every word the pages ask for is there in every language: the literal keys of the
    /// scripts and the HTML, and the keys the therapist page builds from the bridge's names.
    #[test]
    fn every_key_the_pages_use_is_translated() {
        let pages = Pages::new("en");
        let i18n = &pages.get("/assets/i18n.js").expect("i18n").body;
        let (en, de) = i18n.split_once("\n  de: {").expect("en, then de");
        let mut keys: Vec<String> = Vec::new();
        // i18n.js defines the words (its comment shows `data-i18n="key"`); the rest use them.
        for path in pages.paths().filter(|p| *p != "/assets/i18n.js") {
            let body = &pages.get(path).expect(path).body;
            for (open, close) in [("t(\"", "\")"), ("data-i18n=\"", "\"")] {
                for (i, _) in body.match_indices(open) {
                    // `t(` itself, not the end of `createElement(`.
                    let before = body[..i].chars().next_back().unwrap_or(' ');
                    if before.is_alphanumeric() || before == '_' || before == '.' {
                        continue;
                    }
                    let rest = &body[i + open.len()..];
                    // `t("phase_" + ...)` builds its key: only whole literals count here.
                    if let Some(end) = rest.find('"')
                        && rest[end..].starts_with(close)
                    {
                        keys.push(rest[..end].to_string());
                    }
                }
            }
        }
        assert!(keys.len() > 40, "{keys:?}");
        let statuses = ["accepted", "replaced", "timed_out"];
        keys.extend(statuses.map(|s| format!("proposal_{s}")));
        keys.extend(sequence_game::Feedback::ALL.map(|f| format!("fb_{}", f.name())));
        keys.extend(sequence_game::Action::ALL.map(|a| a.key().to_string()));
        for key in keys {
            for (lang, words) in [("en", en), ("de", de)] {
                assert!(
                    words.contains(&format!(" {key}: \"")),
                    "{lang} lacks {key:?}"
                );
            }
        }
    }

    #[test]
    fn every_emotion_has_a_face() {
        let pages = Pages::new("en");
        for e in sequence_game::Emotion::ALL {
            let face = pages
                .get(&format!("/assets/faces/{}.svg", e.name()))
                .expect("face");
            assert!(face.body.starts_with("<svg"), "{}", e.name());
            assert!(
                face.body.contains("<title"),
                "faces need a title for screen readers"
            );
        }
    }
}
