//! Our CSV format of interaction records: one row per solved sequence, columns named in
//! [`CSV_COLUMNS`] (any order; extra columns are ignored), the per-second engagement joined
//! with ';'. Numbers are written in their shortest exact form, so a write-read round trip
//! returns identical records.

use super::{DataError, FieldError, InteractionRecord, in_range};
use sequence_game::{Feedback, Level, Outcome};
use std::path::Path;

/// The columns of our CSV format, in the order we write them.
pub const CSV_COLUMNS: [&str; 11] = [
    "user_id",
    "session_id",
    "time",
    "level",
    "feedback",
    "previous_score",
    "outcome",
    "score",
    "response_time",
    "engagement",
    "engagement_per_second",
];

fn number<T: std::str::FromStr>(field: &'static str, raw: &str) -> Result<T, FieldError> {
    raw.trim()
        .parse::<T>()
        .map_err(|_| FieldError::new(field, format!("{raw:?} is not a valid number")))
}

fn parse_row(get: &dyn Fn(usize) -> String) -> Result<InteractionRecord, FieldError> {
    let game = |field: &'static str| {
        move |e: sequence_game::GameError| FieldError::new(field, e.to_string())
    };
    let level = Level::new(number("level", &get(3))?).map_err(game("level"))?;
    let outcome = Outcome::new(number("outcome", &get(6))?).map_err(game("outcome"))?;
    let engagement = match get(9).trim() {
        "" => None,
        raw => Some(in_range(
            "engagement",
            number("engagement", raw)?,
            -1.0,
            1.0,
        )?),
    };
    let engagement_per_second = get(10)
        .split(';')
        .filter(|s| !s.trim().is_empty())
        .map(|s| {
            in_range(
                "engagement_per_second",
                number("engagement_per_second", s)?,
                -1.0,
                1.0,
            )
        })
        .collect::<Result<Vec<f64>, _>>()?;
    let record = InteractionRecord {
        user_id: get(0),
        session_id: get(1),
        time: number("time", &get(2))?,
        level,
        feedback: Feedback::new(number("feedback", &get(4))?).map_err(game("feedback"))?,
        previous_score: number("previous_score", &get(5))?,
        outcome,
        score: number("score", &get(7))?,
        response_time: number("response_time", &get(8))?,
        engagement,
        engagement_per_second,
    };
    record.validate()?;
    Ok(record)
}

/// Reads records in our CSV format.
pub fn read_csv(path: &Path) -> Result<Vec<InteractionRecord>, DataError> {
    let source = path.display().to_string();
    let mut reader = ::csv::ReaderBuilder::new()
        .from_path(path)
        .map_err(|e| DataError::io(path, e))?;
    let headers: Vec<String> = reader
        .headers()
        .map_err(|e| DataError::io(path, e))?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    let index: Vec<usize> = CSV_COLUMNS
        .iter()
        .map(|c| {
            headers
                .iter()
                .position(|h| h == c)
                .ok_or_else(|| DataError::Column {
                    path: path.into(),
                    column: (*c).into(),
                })
        })
        .collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for (n, row) in reader.records().enumerate() {
        let record = n + 1;
        let row =
            row.map_err(|e| FieldError::new("(row)", e.to_string()).in_record(&source, record))?;
        let get = |i: usize| row.get(index[i]).unwrap_or("").trim().to_string();
        out.push(parse_row(&get).map_err(|e| e.in_record(&source, record))?);
    }
    if out.is_empty() {
        return Err(DataError::Empty { path: path.into() });
    }
    Ok(out)
}

/// Writes records in our CSV format through a temporary file and a rename (never half a file).
pub fn write_csv(path: &Path, records: &[InteractionRecord]) -> Result<(), DataError> {
    super::validate_all(records)?;
    let mut bytes = Vec::new();
    {
        let mut w = ::csv::Writer::from_writer(&mut bytes);
        let fail = |e: ::csv::Error| DataError::io(path, e);
        w.write_record(CSV_COLUMNS).map_err(fail)?;
        for r in records {
            let per_second: Vec<String> =
                r.engagement_per_second.iter().map(f64::to_string).collect();
            w.write_record([
                r.user_id.clone(),
                r.session_id.clone(),
                r.time.to_string(),
                r.level.get().to_string(),
                u8::from(r.feedback).to_string(),
                r.previous_score.to_string(),
                r.outcome.sign().to_string(),
                r.score.to_string(),
                r.response_time.to_string(),
                r.engagement.map(|e| e.to_string()).unwrap_or_default(),
                per_second.join(";"),
            ])
            .map_err(fail)?;
        }
        w.flush().map_err(|e| DataError::io(path, e))?;
    }
    atomic_file::write(path, &bytes).map_err(|e| DataError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{StudySpec, simulate_study};

    #[test]
    fn write_then_read_gives_identical_records() {
        let records = simulate_study(&StudySpec::default());
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("records.csv");
        write_csv(&path, &records).expect("writes");
        assert_eq!(read_csv(&path).expect("reads"), records);
    }

    #[test]
    fn bad_values_are_named_by_record_and_field() {
        let records = simulate_study(&StudySpec::default());
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("records.csv");
        write_csv(&path, &records[..3]).expect("writes");
        let good = std::fs::read_to_string(&path).expect("reads");
        let rows: Vec<&str> = good.lines().collect();
        let cases = [
            (1, 2, "NaN", "time"),
            (2, 3, "4", "level"),
            (3, 4, "7", "feedback"),
            (1, 5, "5", "previous_score"),
            (2, 6, "0", "outcome"),
            (3, 7, "9", "score"),
            (1, 8, "-2", "response_time"),
            (2, 9, "1.5", "engagement"),
            (3, 10, "0.1;nan", "engagement_per_second"),
            (1, 0, "", "user_id"),
        ];
        for (record, column, value, field) in cases {
            let mut cells: Vec<String> = rows[record].split(',').map(str::to_string).collect();
            cells[column] = value.to_string();
            let mut lines: Vec<String> = rows.iter().map(|s| s.to_string()).collect();
            lines[record] = cells.join(",");
            std::fs::write(&path, lines.join("\n")).expect("writes");
            let e = read_csv(&path).expect_err(field).to_string();
            assert!(
                e.contains(&format!("record {record}, field {field}:")),
                "{field}: {e}"
            );
        }
        std::fs::write(&path, "user_id,time\nu,1\n").expect("writes");
        assert!(matches!(read_csv(&path), Err(DataError::Column { .. })));
        std::fs::write(&path, rows[0]).expect("writes");
        assert!(matches!(read_csv(&path), Err(DataError::Empty { .. })));
    }

    #[test]
    fn a_failed_write_leaves_the_old_file() {
        let records = simulate_study(&StudySpec::default());
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("records.csv");
        write_csv(&path, &records).expect("writes");
        let before = std::fs::read(&path).expect("reads");
        let mut bad = records.clone();
        bad[150].engagement = Some(f64::NAN);
        let e = write_csv(&path, &bad).expect_err("NaN engagement");
        assert!(
            e.to_string().contains("record 151, field engagement"),
            "{e}"
        );
        assert_eq!(std::fs::read(&path).expect("reads"), before);
        assert_eq!(std::fs::read_dir(dir.path()).expect("lists").count(), 1);
    }
}
