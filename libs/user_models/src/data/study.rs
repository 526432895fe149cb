//! The MigrAVE study's own files, read directly: `sequences.csv` (one row per solved sequence)
//! and `engagement_per_second.csv`. PS is the previous sequence's score (±L) of the same
//! participant in sequence order, 0 for the first; E is the row's `eng_qt`, the authors' mean
//! expected engagement while the robot talked (their smoothing, kept as they computed it); the
//! per-second values are those of the seconds in [start, start + talking_time).

use super::{DataError, FieldError, InteractionRecord, in_range};
use sequence_game::{Feedback, Level, Outcome};
use std::collections::BTreeMap;
use std::path::Path;

fn open(path: &Path) -> Result<(::csv::Reader<std::fs::File>, Vec<String>), DataError> {
    let mut reader = ::csv::ReaderBuilder::new()
        .trim(::csv::Trim::All)
        .from_path(path)
        .map_err(|e| DataError::io(path, e))?;
    let headers = reader
        .headers()
        .map_err(|e| DataError::io(path, e))?
        .iter()
        .map(str::to_string)
        .collect();
    Ok((reader, headers))
}

fn columns<const N: usize>(
    path: &Path,
    headers: &[String],
    names: [&str; N],
) -> Result<[usize; N], DataError> {
    let mut out = [0; N];
    for (slot, name) in out.iter_mut().zip(names) {
        *slot = headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| DataError::Column {
                path: path.into(),
                column: name.into(),
            })?;
    }
    Ok(out)
}

fn number<T: std::str::FromStr>(
    row: &::csv::StringRecord,
    i: usize,
    field: &'static str,
) -> Result<T, FieldError> {
    let raw = row.get(i).unwrap_or("");
    raw.parse::<T>()
        .map_err(|_| FieldError::new(field, format!("{raw:?} is not a valid number")))
}

/// Reads the study directory `dir`.
pub fn read_study(dir: &Path) -> Result<Vec<InteractionRecord>, DataError> {
    let seq_path = dir.join("sequences.csv");
    let eng_path = dir.join("engagement_per_second.csv");
    let eng_source = eng_path.display().to_string();
    let seq_source = seq_path.display().to_string();

    let mut per_second: BTreeMap<String, BTreeMap<i64, f64>> = BTreeMap::new();
    let (mut reader, headers) = open(&eng_path)?;
    let [p, s, e] = columns(&eng_path, &headers, ["participant_id", "secs", "eng_qt"])?;
    for (n, row) in reader.records().enumerate() {
        let parsed = (|| -> Result<(String, i64, f64), FieldError> {
            let row = row.map_err(|e| FieldError::new("(row)", e.to_string()))?;
            let secs: f64 = number(&row, s, "secs")?;
            let value = in_range("eng_qt", number(&row, e, "eng_qt")?, -1.0, 1.0)?;
            Ok((
                row.get(p).unwrap_or("").to_string(),
                in_range("secs", secs, 0.0, 1e12)? as i64,
                value,
            ))
        })()
        .map_err(|e| e.in_record(&eng_source, n + 1))?;
        per_second
            .entry(parsed.0)
            .or_default()
            .insert(parsed.1, parsed.2);
    }

    let (mut reader, headers) = open(&seq_path)?;
    let cols = columns(
        &seq_path,
        &headers,
        [
            "participant_id",
            "secs",
            "id",
            "length",
            "correct",
            "feedback",
            "duration",
            "eng_qt",
            "start",
            "talking_time",
        ],
    )?;
    // (participant, sequence index, file record number, record)
    let mut rows: Vec<(String, i64, usize, InteractionRecord)> = Vec::new();
    for (n, row) in reader.records().enumerate() {
        let record = n + 1;
        let parsed = (|| -> Result<(String, i64, InteractionRecord), FieldError> {
            let row = row.map_err(|e| FieldError::new("(row)", e.to_string()))?;
            let user = row.get(cols[0]).unwrap_or("").to_string();
            let game = |field: &'static str| {
                move |e: sequence_game::GameError| FieldError::new(field, e.to_string())
            };
            let level = Level::from_sequence_length(number(&row, cols[3], "length")?)
                .map_err(game("length"))?;
            let outcome = match number::<i64>(&row, cols[4], "correct")? {
                0 => Outcome::Failure,
                1 => Outcome::Success,
                other => return Err(FieldError::new("correct", format!("{other} is not 0 or 1"))),
            };
            let feedback =
                Feedback::new(number(&row, cols[5], "feedback")?).map_err(game("feedback"))?;
            let start = in_range("start", number(&row, cols[8], "start")?, 0.0, 1e12)?;
            let talking = in_range(
                "talking_time",
                number(&row, cols[9], "talking_time")?,
                0.0,
                3600.0,
            )?;
            let index: i64 = number(&row, cols[2], "id")?;
            let r = InteractionRecord {
                user_id: user.clone(),
                session_id: format!("{user}-study"),
                time: number(&row, cols[1], "secs")?,
                level,
                feedback,
                previous_score: 0,
                outcome,
                score: outcome.score(level),
                response_time: in_range(
                    "duration",
                    number(&row, cols[6], "duration")?,
                    0.0,
                    86_400.0,
                )?,
                engagement: Some(in_range(
                    "eng_qt",
                    number(&row, cols[7], "eng_qt")?,
                    -1.0,
                    1.0,
                )?),
                engagement_per_second: per_second
                    .get(&user)
                    .map(|m| {
                        m.range(start as i64..(start + talking) as i64)
                            .map(|(_, v)| *v)
                            .collect()
                    })
                    .unwrap_or_default(),
            };
            r.validate()?;
            Ok((user, index, r))
        })()
        .map_err(|e| e.in_record(&seq_source, record))?;
        rows.push((parsed.0, parsed.1, record, parsed.2));
    }
    if rows.is_empty() {
        return Err(DataError::Empty { path: seq_path });
    }
    rows.sort_by(|a, b| (a.0.as_str(), a.1).cmp(&(b.0.as_str(), b.1)));
    let mut out: Vec<InteractionRecord> = Vec::with_capacity(rows.len());
    let mut last: Option<(String, i64)> = None;
    for (user, index, record, mut r) in rows {
        if last.as_ref() == Some(&(user.clone(), index)) {
            return Err(
                FieldError::new("id", format!("sequence {index} of {user} appears twice"))
                    .in_record(&seq_source, record),
            );
        }
        r.previous_score = match out.last() {
            Some(prev) if prev.user_id == user => prev.score,
            _ => 0,
        };
        last = Some((user, index));
        out.push(r);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, sequences: &str) {
        std::fs::write(
            dir.join("engagement_per_second.csv"),
            "participant_id,secs,eng_qt\nA,100,0.5\nA,101,-0.5\nA,130,0.25\nB,100,1.0\n",
        )
        .expect("writes");
        std::fs::write(dir.join("sequences.csv"), sequences).expect("writes");
    }

    const HEADER: &str =
        "participant_id,secs,id,length,correct,feedback,duration,eng_qt,start,talking_time\n";

    #[test]
    fn previous_score_follows_sequence_order_per_participant() {
        let dir = tempfile::tempdir().expect("temp dir");
        write(
            dir.path(),
            &format!(
                "{HEADER}A,140,1,7,0,2,  9.5,  0.2,130,20\nA,120,0,5,1,0,12.0,0.4,100,8\nB,120,0,3,0,0,5.0,1.0,100,8\n"
            ),
        );
        let r = read_study(dir.path()).expect("reads");
        assert_eq!(r.len(), 3);
        assert_eq!(
            (r[0].user_id.as_str(), r[0].previous_score, r[0].score),
            ("A", 0, 2)
        );
        assert_eq!(
            (r[1].previous_score, r[1].score, r[1].feedback),
            (2, -3, Feedback::Challenging)
        );
        assert_eq!(r[0].engagement_per_second, [0.5, -0.5]);
        assert_eq!(r[1].engagement_per_second, [0.25]);
        assert_eq!((r[2].user_id.as_str(), r[2].previous_score), ("B", 0));
        assert_eq!(r[1].response_time, 9.5);
    }

    #[test]
    fn bad_rows_are_named() {
        let dir = tempfile::tempdir().expect("temp dir");
        for (row, field) in [
            ("A,120,0,4,1,0,12.0,0.4,100,8", "length"),
            ("A,120,0,5,2,0,12.0,0.4,100,8", "correct"),
            ("A,120,0,5,1,0,12.0,NaN,100,8", "eng_qt"),
            ("A,120,0,5,1,3,12.0,0.4,100,8", "feedback"),
            ("A,120,0,5,1,0,-1,0.4,100,8", "duration"),
        ] {
            write(
                dir.path(),
                &format!("{HEADER}A,110,1,3,1,0,3.0,0.1,100,8\n{row}\n"),
            );
            let e = read_study(dir.path()).expect_err(field).to_string();
            assert!(
                e.contains(&format!("sequences.csv, record 2, field {field}:")),
                "{e}"
            );
        }
        write(
            dir.path(),
            &format!("{HEADER}A,110,1,3,1,0,3.0,0.1,100,8\nA,120,1,5,1,0,12.0,0.4,100,8\n"),
        );
        let e = read_study(dir.path()).expect_err("duplicate").to_string();
        assert!(e.contains("appears twice"), "{e}");
    }
}
