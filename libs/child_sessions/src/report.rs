//! A child's progress as HTML, in English or German: what the robot believes now, what could
//! not be read, the figures across sessions (`figures::progress`) with a caption each, and a
//! table with one row per session. [`progress_fragment`] is the body (the therapist page shows
//! it as it is, styled by [`STYLESHEET`], which the bridge serves); [`progress_document`] is
//! the same body in a self-contained page with the stylesheet inlined, which prints on A4
//! (`session_report --user`). Everything from a file is escaped; the figures are SVG with
//! presentation attributes only, so the page's Content-Security-Policy (no inline style or
//! script) lets them through.

use crate::progress::{Belief, BeliefAt, CarriedBelief, Progress, SessionProgress};
use crate::words::word;
use figures::progress::{
    BeliefBar, BeliefWords, ProgressWords, SessionPoint, belief_svg,
    engagement_across_sessions_svg, score_and_level_svg,
};
use sequence_game::Level;
use std::fmt::Write as _;

/// The report's stylesheet: inlined in the document, served to the therapist page.
pub const STYLESHEET: &str = include_str!("../assets/progress.css");

/// A language the tablet pages ship.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Language {
    En,
    De,
}

impl Language {
    /// `en` or `de`; None for any other code.
    pub fn from_code(code: &str) -> Option<Language> {
        match code {
            "en" => Some(Language::En),
            "de" => Some(Language::De),
            _ => None,
        }
    }

    pub fn code(self) -> &'static str {
        match self {
            Language::En => "en",
            Language::De => "de",
        }
    }
}

/// Text for HTML (element content and attribute values).
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

/// `YYYY-MM-DD HH:MM` (UTC) of nanoseconds since the epoch.
pub fn date_time(ns: i64) -> String {
    match time::OffsetDateTime::from_unix_timestamp_nanos(i128::from(ns)) {
        Ok(t) => format!(
            "{:04}-{:02}-{:02} {:02}:{:02}",
            t.year(),
            u8::from(t.month()),
            t.day(),
            t.hour(),
            t.minute()
        ),
        Err(_) => format!("{} s after the epoch", ns / 1_000_000_000),
    }
}

/// `YYYY-MM-DD` (UTC).
fn date(ns: i64) -> String {
    date_time(ns).chars().take(10).collect()
}

fn point(s: &SessionProgress) -> SessionPoint {
    SessionPoint {
        score: s.tally.score,
        max_score: s.tally.max_score,
        levels: s.levels(),
        engagement: s.engagement(),
    }
}

/// An SVG figure named by its caption for screen readers.
fn figure(svg: &str, id: &str, caption: &str) -> String {
    let svg = svg.replacen(
        "<svg ",
        &format!("<svg role=\"img\" aria-labelledby=\"{id}\" "),
        1,
    );
    format!(
        "<figure>{svg}<figcaption id=\"{id}\">{}</figcaption></figure>",
        escape(caption)
    )
}

/// `template` with each `{name}` replaced by its value.
fn filled(template: &str, values: &[(&str, String)]) -> String {
    values
        .iter()
        .fold(template.to_string(), |t, (name, value)| {
            t.replace(&format!("{{{name}}}"), value)
        })
}

/// A chance as whole percent.
fn percent(p: f64) -> String {
    format!("{:.0}", p * 100.0)
}

/// What the robot believes about the child, in words and a small picture (the words are the
/// picture's text alternative: the figure's caption points to them).
fn belief_said(p: &Progress, lang: Language) -> String {
    let w = |key| word(lang, key);
    let b: &CarriedBelief = match &p.belief {
        Belief::NoDecisions => {
            return format!(
                "<div class=\"said\"><p>{}</p></div>",
                w("belief_no_decisions")
            );
        }
        Belief::NotCarried => {
            return format!(
                "<div class=\"said\"><p>{}</p></div>",
                w("belief_not_carried")
            );
        }
        Belief::Carried(b) => b,
    };
    let date = p
        .sessions
        .get(b.session_number.saturating_sub(1))
        .and_then(|s| s.started_ns)
        .map(date)
        .unwrap_or_else(|| b.session_id.clone());
    let mut html = String::from("<div class=\"said\">");
    let _ = write!(
        html,
        "<p>{}</p><ul>",
        escape(&filled(
            w("belief_intro"),
            &[
                ("session", b.session_number.to_string()),
                ("date", date),
                ("observations", b.now.observations.to_string()),
            ]
        ))
    );
    for (level, now) in Level::ALL.iter().zip(&b.now.levels) {
        let line = filled(
            w("belief_level"),
            &[
                ("level", level.get().to_string()),
                ("length", level.sequence_length().to_string()),
                ("right", percent(now.success)),
                ("right_sd", percent(now.success_sd)),
                ("engagement", format!("{:+.2}", now.engagement)),
                ("engagement_sd", format!("{:.2}", now.engagement_sd)),
            ],
        );
        let _ = write!(html, "<li>{}</li>", escape(&line));
    }
    let _ = write!(html, "</ul><p>{}</p><ul>", w("belief_moved"));
    for ((level, from), to) in Level::ALL
        .iter()
        .zip(&b.session_start.levels)
        .zip(&b.now.levels)
    {
        let line = filled(
            w("belief_moved_level"),
            &[
                ("level", level.get().to_string()),
                ("from", percent(from.success)),
                ("to", percent(to.success)),
                ("from_e", format!("{:+.2}", from.engagement)),
                ("to_e", format!("{:+.2}", to.engagement)),
            ],
        );
        let _ = write!(html, "<li>{}</li>", escape(&line));
    }
    let _ = write!(
        html,
        "</ul><p>{}</p></div>",
        escape(&filled(
            w("belief_left_table"),
            &[
                ("left", b.left_table.to_string()),
                ("planned", b.planned.to_string()),
            ]
        ))
    );
    let words = BeliefWords {
        title: w("belief_figure_title"),
        right: w("belief_figure_right"),
        level: w("level"),
        now: w("belief_figure_now"),
        session_start: w("belief_figure_start"),
    };
    match belief_svg(&belief_bars(&b.now, &b.session_start), &words) {
        Ok(svg) => html.push_str(&figure(
            &svg,
            "progress-belief-caption",
            w("belief_caption"),
        )),
        Err(e) => {
            let _ = write!(
                html,
                "<p>{}: {}</p>",
                w("belief_figure_title"),
                escape(&e.to_string())
            );
        }
    }
    html
}

/// The figure's bars, in percent.
fn belief_bars(now: &BeliefAt, start: &BeliefAt) -> [BeliefBar; 3] {
    std::array::from_fn(|k| BeliefBar {
        now: now.levels[k].success * 100.0,
        now_sd: now.levels[k].success_sd * 100.0,
        session_start: start.levels[k].success * 100.0,
    })
}

/// The report's body: an `<article>` whose title is a heading of level `top` (1 alone, 2
/// inside the therapist page), made at `as_of_ns` (ns since the epoch).
pub fn progress_fragment(p: &Progress, lang: Language, top: u8, as_of_ns: i64) -> String {
    let w = |key| word(lang, key);
    let (h1, h2) = (top.clamp(1, 5), top.clamp(1, 5) + 1);
    let user = escape(p.user.as_str());
    let mut html = String::new();
    let _ = write!(
        html,
        "<article class=\"progress\" lang=\"{}\" data-user=\"{user}\" data-sessions=\"{}\">\
         <h{h1}>{} {user}</h{h1}>",
        lang.code(),
        p.sessions.len(),
        w("progress_of")
    );
    let places: Vec<String> = p
        .places
        .iter()
        .map(|d| escape(&d.display().to_string()))
        .collect();
    let count = match p.sessions.len() {
        1 => format!("1 {}", w("session_word")),
        n => format!("{n} {}", w("sessions_word")),
    };
    let span = p
        .span_ns()
        .map(|(a, b)| {
            if date(a) == date(b) {
                format!(", {}", date(a))
            } else {
                format!(", {} {} {}", date(a), w("to"), date(b))
            }
        })
        .unwrap_or_default();
    let _ = write!(
        html,
        "<p class=\"meta\">{count}{span}. {} {} ({} {} UTC).</p>",
        w("from_stored"),
        places.join(", "),
        w("as_of"),
        date_time(as_of_ns)
    );
    let _ = write!(
        html,
        "<section class=\"belief\"><h{h2}>{}</h{h2}>{}</section>",
        w("belief_title"),
        belief_said(p, lang)
    );
    if !p.problems.is_empty() {
        let _ = write!(
            html,
            "<section class=\"problems\"><h{h2}>{}</h{h2}>",
            w("problems_title")
        );
        // Marked as English for a screen reader reading a German page (WCAG 3.1.2).
        if lang == Language::En {
            html.push_str("<ul>");
        } else {
            let _ = write!(html, "<p>{}</p><ul lang=\"en\">", w("problems_in_english"));
        }
        for problem in &p.problems {
            let _ = write!(html, "<li>{}</li>", escape(problem));
        }
        html.push_str("</ul></section>");
    }
    if p.sessions.is_empty() {
        let _ = write!(
            html,
            "<p class=\"empty\">{}</p></article>",
            w("no_sessions")
        );
        return html;
    }
    let points: Vec<SessionPoint> = p.sessions.iter().map(point).collect();
    let words = ProgressWords {
        score_title: w("score_title"),
        engagement_title: w("engagement_title"),
        session: w("session"),
        score: w("score"),
        best_possible: w("best_possible"),
        level: w("level"),
        mean_and_range: w("mean_and_range"),
        engagement: w("engagement"),
    };
    let _ = write!(
        html,
        "<section class=\"across\"><h{h2}>{}</h{h2}>",
        w("across_title")
    );
    // A figure that cannot be drawn is named in its place; the table still shows the numbers.
    match score_and_level_svg(&points, &words) {
        Ok(svg) => html.push_str(&figure(&svg, "progress-score-caption", w("score_caption"))),
        Err(e) => {
            let _ = write!(
                html,
                "<p>{}: {}</p>",
                w("score_title"),
                escape(&e.to_string())
            );
        }
    }
    match engagement_across_sessions_svg(&points, &words) {
        Ok(svg) => html.push_str(&figure(
            &svg,
            "progress-engagement-caption",
            w("engagement_caption"),
        )),
        Err(e) => {
            let _ = write!(
                html,
                "<p>{}: {}</p>",
                w("engagement_title"),
                escape(&e.to_string())
            );
        }
    }
    html.push_str("</section>");
    let _ = write!(
        html,
        "<section class=\"sessions\"><h{h2} id=\"progress-table-title\">{}</h{h2}>\
         <div class=\"table\" role=\"region\" aria-labelledby=\"progress-table-title\" \
         tabindex=\"0\"><table><thead><tr>",
        w("per_session_title")
    );
    for key in [
        "col_number",
        "col_started",
        "col_score",
        "col_right",
        "col_levels",
        "col_engagement",
        "col_feedback",
        "col_overrides",
        "col_pauses",
        "col_proposals",
        "col_ended",
    ] {
        let _ = write!(html, "<th scope=\"col\">{}</th>", w(key));
    }
    html.push_str("</tr></thead><tbody>");
    for (k, s) in p.sessions.iter().enumerate() {
        session_row(&mut html, k + 1, s, lang);
    }
    html.push_str("</tbody></table></div></section></article>");
    html
}

fn session_row(html: &mut String, number: usize, s: &SessionProgress, lang: Language) {
    let w = |key| word(lang, key);
    let t = &s.tally;
    let levels = if s.results.is_empty() {
        w("none_played").to_string()
    } else {
        s.levels()
            .iter()
            .map(u8::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    };
    let engagement = t
        .mean_engagement
        .map_or_else(|| w("no_face").to_string(), |e| format!("{e:+.2}"));
    let proposals = s.proposals.map_or_else(
        || w("not_recorded").to_string(),
        |c| {
            if c.proposed == 0 {
                "0".to_string()
            } else {
                format!(
                    "{}: {}/{}/{}",
                    c.proposed, c.accepted, c.replaced, c.timed_out
                )
            }
        },
    );
    let mut ended = w(s.ended.key()).to_string();
    if s.recovered > 0 {
        ended = format!("{ended}; {}", w("recovered"));
    }
    let started = s.started_ns.map(date_time).unwrap_or_default();
    let _ = write!(
        html,
        "<tr data-session=\"{}\"><td>{number}</td><td class=\"when\" title=\"{}\">{started}</td>\
         <td class=\"score\">{} / {}</td><td>{} / {}</td><td class=\"levels\">{levels}</td>\
         <td>{engagement}</td><td>{} / {}</td><td>{}</td><td>{}</td><td>{proposals}</td>\
         <td class=\"ended\">{}</td></tr>",
        escape(&s.session_id),
        escape(&s.session_id),
        t.score,
        t.max_score,
        t.correct,
        t.sequences,
        s.encouraging,
        s.challenging,
        s.overrides,
        s.pauses,
        escape(&ended)
    );
}

/// The meta element naming whose progress a report file is (`child_data` finds the files of
/// a child by it: [`progress_report_of`]).
const WHOSE: &str = "<meta name=\"qt-therapy-progress-of\" content=\"";

/// The whole report as one self-contained page (stylesheet inlined, figures inline, nothing
/// fetched), for a file to print or hand over.
pub fn progress_document(p: &Progress, lang: Language, as_of_ns: i64) -> String {
    let user = escape(p.user.as_str());
    format!(
        "<!doctype html><html lang=\"{}\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         {WHOSE}{user}\"><title>{} {user}</title><style>{STYLESHEET}</style></head>\
         <body><main>{}</main></body></html>\n",
        lang.code(),
        word(lang, "progress_of"),
        progress_fragment(p, lang, 1, as_of_ns)
    )
}

/// Whose progress `html` is, when it is a progress report [`progress_document`] wrote.
pub fn progress_report_of(html: &str) -> Option<String> {
    let start = html.find(WHOSE)? + WHOSE.len();
    let end = start + html[start..].find('"')?;
    Some(
        html[start..end]
            .replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&quot;", "\"")
            .replace("&#39;", "'")
            .replace("&amp;", "&"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::words::KEYS;

    #[test]
    fn a_report_file_says_whose_progress_it_is() {
        let user = crate::UserId::new("a\"b<c").expect("id");
        let p = Progress {
            user: user.clone(),
            places: Vec::new(),
            sessions: Vec::new(),
            problems: Vec::new(),
            last_decision: None,
            belief: Belief::NotCarried,
        };
        let html = progress_document(&p, Language::De, 0);
        assert_eq!(progress_report_of(&html).as_deref(), Some(user.as_str()));
        assert_eq!(
            progress_report_of("<html><title>Session s — user u</title>"),
            None
        );
    }

    #[test]
    fn the_readers_english_messages_are_marked_as_english_on_a_german_page() {
        let p = Progress {
            user: crate::UserId::new("child-7").expect("id"),
            places: Vec::new(),
            sessions: Vec::new(),
            problems: vec!["no bag in run-4".into()],
            last_decision: None,
            belief: Belief::NotCarried,
        };
        let de = progress_fragment(&p, Language::De, 2, 0);
        assert!(
            de.contains("stehen auf Englisch")
                && de.contains("<ul lang=\"en\"><li>no bag in run-4"),
            "{de}"
        );
        let en = progress_fragment(&p, Language::En, 2, 0);
        assert!(en.contains("<ul><li>no bag in run-4") && !en.contains("lang=\"en\"><li>"));
    }

    fn carried() -> Progress {
        use crate::progress::{CarriedBelief, LevelBelief};
        let at = |right: [f64; 3], observations| BeliefAt {
            observations,
            levels: std::array::from_fn(|k| LevelBelief {
                success: right[k],
                success_sd: [0.06, 0.1, 0.15][k],
                engagement: [0.4, 0.2, -0.1][k],
                engagement_sd: [0.1, 0.12, 0.2][k],
            }),
        };
        Progress {
            user: crate::UserId::new("child-7").expect("id"),
            places: Vec::new(),
            sessions: Vec::new(),
            problems: Vec::new(),
            last_decision: None,
            belief: Belief::Carried(Box::new(CarriedBelief {
                session_id: "tablet-1".into(),
                session_number: 3,
                now: at([0.85, 0.68, 0.31], 29),
                session_start: at([0.8, 0.55, 0.3], 20),
                planned: 10,
                left_table: 3,
            })),
        }
    }

    #[test]
    fn the_belief_is_said_in_words_and_drawn_in_both_languages() {
        let p = carried();
        let en = progress_fragment(&p, Language::En, 2, 0);
        for said in [
            "after 29 sequences of the child&#39;s own",
            "Level 1 (3 emotions): right about 85\u{a0}% of the time (±\u{a0}6), engagement +0.40 \
             (±\u{a0}0.10)",
            "Level 3 (7 emotions): right about 31\u{a0}% of the time (±\u{a0}15), engagement -0.10 \
             (±\u{a0}0.20)",
            "level 2: 55\u{a0}% → 68\u{a0}% right, engagement +0.20 → +0.20",
            "chose differently from the group&#39;s table in 3 of 10 sequences",
        ] {
            assert!(en.contains(said), "{said}\n{en}");
        }
        // The picture, named by its caption.
        assert!(
            en.contains("<svg role=\"img\" aria-labelledby=\"progress-belief-caption\"")
                && en.contains("<figcaption id=\"progress-belief-caption\">Per level"),
            "{en}"
        );
        let de = progress_fragment(&p, Language::De, 2, 0);
        for said in [
            "nach 29 eigenen Sequenzen des Kindes",
            "Level 2 (5 Emotionen): etwa 68\u{a0}% der Antworten richtig (±\u{a0}10), Engagement \
             +0.20 (±\u{a0}0.12)",
            "Level 1: 80\u{a0}% → 85\u{a0}% richtig",
            "in 3 von 10 Sequenzen anders als die Tabelle der Gruppe",
            "Chance einer richtigen Antwort je Level",
        ] {
            assert!(de.contains(said), "{said}\n{de}");
        }
        let not_carried = Progress {
            belief: Belief::NotCarried,
            ..carried()
        };
        let en = progress_fragment(&not_carried, Language::En, 2, 0);
        assert!(
            en.contains("Not available: the robot did not learn about this child")
                && en.contains("table of its group of children")
                && !en.contains("progress-belief-caption"),
            "{en}"
        );
        let de = progress_fragment(&not_carried, Language::De, 2, 0);
        assert!(de.contains("Tabelle seiner Gruppe"), "{de}");
    }

    /// Every key the report looks up is in `words` in both languages.
    #[test]
    fn every_key_used_is_a_word() {
        let source = include_str!("report.rs");
        let used: Vec<&str> = source
            .match_indices("w(\"")
            // `w(` itself, not the end of `new(`.
            .filter(|(i, _)| {
                source[..*i]
                    .chars()
                    .next_back()
                    .is_some_and(|c| !c.is_alphanumeric() && c != '_')
            })
            .filter_map(|(i, _)| {
                let rest = &source[i + 3..];
                rest.find('"').map(|end| &rest[..end])
            })
            .collect();
        assert!(used.len() > 20, "{used:?}");
        for key in used.iter().copied().chain(KEYS.iter().copied()) {
            for lang in [Language::En, Language::De] {
                assert!(!word(lang, key).is_empty(), "{lang:?} lacks {key:?}");
            }
        }
    }

    #[test]
    fn dates_are_utc() {
        assert_eq!(date_time(0), "1970-01-01 00:00");
        assert_eq!(date_time(1_778_333_400_000_000_000), "2026-05-09 13:30");
    }
}
