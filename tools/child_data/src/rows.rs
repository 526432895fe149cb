//! A user's part of a text file, as byte ranges of the original, so what is exported is the
//! file's own bytes and what erase keeps is byte for byte what was there:
//! - interaction CSVs (`libs/user_models/src/data/csv_file.rs`, a `user_id` column; the
//!   MigrAVE study's files name it `participant_id`): the rows whose id cell is the user's;
//! - logs: the lines naming the user (or one of the user's sessions);
//! - the session report's title, which says whose session it is.

use std::ops::Range;

/// A CSV split into its header and rows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvRows {
    /// The column holding the user id.
    pub column: String,
    /// The header line, with its line end.
    pub header: Range<usize>,
    /// Every row (with its line end), and whether it is the user's.
    pub rows: Vec<(Range<usize>, bool)>,
}

impl CsvRows {
    pub fn users_rows(&self) -> usize {
        self.rows.iter().filter(|(_, u)| *u).count()
    }
}

/// The column names that hold a user id.
pub const USER_COLUMNS: [&str; 2] = ["user_id", "participant_id"];

/// Splits `bytes` (a CSV with a header) into rows, marking those whose user column is `user`;
/// `Ok(None)` when no column holds a user id, an error naming the row that does not parse.
pub fn csv_rows(bytes: &[u8], user: &str) -> Result<Option<CsvRows>, String> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(bytes);
    let mut records = reader.byte_records();
    let Some(header) = records.next() else {
        return Ok(None);
    };
    let header = header.map_err(|e| format!("the header: {e}"))?;
    let Some((index, column)) = header.iter().enumerate().find_map(|(i, h)| {
        let h = String::from_utf8_lossy(h).trim().to_string();
        USER_COLUMNS.contains(&h.as_str()).then_some((i, h))
    }) else {
        return Ok(None);
    };
    let mut starts = Vec::new();
    let mut owned = Vec::new();
    for (n, record) in records.enumerate() {
        let record = record.map_err(|e| format!("row {}: {e}", n + 1))?;
        // After a `\r\n` the reader's position is at the `\n`: the row starts after it.
        let mut start = record.position().map_or(0, |p| p.byte() as usize);
        while matches!(bytes.get(start), Some(b'\r' | b'\n')) {
            start += 1;
        }
        let cell = record
            .get(index)
            .map(|c| String::from_utf8_lossy(c).trim().to_string());
        starts.push(start);
        owned.push(cell.as_deref() == Some(user));
    }
    let header_end = starts.first().copied().unwrap_or(bytes.len());
    let mut rows = Vec::with_capacity(starts.len());
    for (k, start) in starts.iter().enumerate() {
        let end = starts.get(k + 1).copied().unwrap_or(bytes.len());
        rows.push((*start..end, owned[k]));
    }
    Ok(Some(CsvRows {
        column,
        header: 0..header_end,
        rows,
    }))
}

/// Every line of `text` with its line end, and whether `pick` takes it.
pub fn lines(text: &str, pick: &dyn Fn(&str) -> bool) -> Vec<(Range<usize>, bool)> {
    let mut out = Vec::new();
    let mut start = 0;
    for line in text.split_inclusive('\n') {
        let end = start + line.len();
        out.push((start..end, pick(line)));
        start = end;
    }
    out
}

/// The bytes of `source` in the ranges `parts` picks (`want` true: the picked ones).
pub fn gather<'a>(
    source: &[u8],
    parts: impl IntoIterator<Item = &'a (Range<usize>, bool)>,
    want: bool,
) -> Vec<u8> {
    let mut out = Vec::new();
    for (r, picked) in parts {
        if *picked == want {
            out.extend_from_slice(&source[r.clone()]);
        }
    }
    out
}

/// The session and user a session report is about, from its title
/// (`<title>Session {session} — user {user}</title>`, HTML-escaped, as
/// `tools/session_report/src/lib.rs` writes it).
pub fn report_title(html: &str) -> Option<(String, String)> {
    let start = html.find("<title>Session ")? + "<title>Session ".len();
    let end = start + html[start..].find("</title>")?;
    let (session, user) = html[start..end].rsplit_once(" — user ")?;
    Some((html_unescape(session), html_unescape(user)))
}

fn html_unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_rows_keep_their_bytes_quotes_and_line_ends() {
        let text = "user_id,session_id,note\r\na,s1,\"x\ny\"\r\nb,s2,z\r\n a ,s3,w";
        let rows = csv_rows(text.as_bytes(), "a")
            .expect("parses")
            .expect("a user column");
        assert_eq!(rows.column, "user_id");
        assert_eq!(rows.users_rows(), 2);
        let mine = gather(text.as_bytes(), &rows.rows, true);
        let rest = gather(text.as_bytes(), &rows.rows, false);
        assert_eq!(
            String::from_utf8(mine).expect("utf8"),
            "a,s1,\"x\ny\"\r\n a ,s3,w"
        );
        assert_eq!(String::from_utf8(rest).expect("utf8"), "b,s2,z\r\n");
        assert_eq!(&text[rows.header.clone()], "user_id,session_id,note\r\n");
        assert!(
            csv_rows(b"frame,AU01\n1,0.5\n", "a")
                .expect("parses")
                .is_none()
        );
        let study = csv_rows(b"participant_id,secs\n1CZ1CL1P,1\n", "1CZ1CL1P")
            .expect("parses")
            .expect("column");
        assert_eq!(
            (study.column.as_str(), study.users_rows()),
            ("participant_id", 1)
        );
    }

    #[test]
    fn lines_and_report_titles() {
        let text = "a child-7\nb\nc child-7";
        let picked = lines(text, &|l| l.contains("child-7"));
        assert_eq!(gather(text.as_bytes(), &picked, false), b"b\n".to_vec());
        assert_eq!(
            report_title("<html><head><title>Session s &amp; 1 — user a&lt;b</title>"),
            Some(("s & 1".to_string(), "a<b".to_string()))
        );
        assert_eq!(report_title("<title>Other</title>"), None);
    }
}
