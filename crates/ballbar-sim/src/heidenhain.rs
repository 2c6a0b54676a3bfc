//! A HEIDENHAIN TNC's nonlinear axis error compensation, emulated from its technical manual for
//! `simulate --compensation DIR`: compensation value tables (`*.COM`) assigned to the axes by
//! the active row of a `*.CMA` table.
//!
//! Written from the manual, independently of the code that writes the files
//! (`ballbar-compensate`):
//! - a table file is `BEGIN <name> [MM|INCH]`, a line of column names, one row a line, `[END]`;
//!   a `DOC` column, the last, holds text;
//! - the `.CMA`'s row marked `*` in `ACTIVE` names, in each axis's column, the `.COM` table
//!   that compensates that axis;
//! - a `.COM` table's `AXISPOS` column holds the compensation points (machine coordinates,
//!   ascending), the axis's column the error there moving positive, `BACKLASH` (if present)
//!   moving negative; at most 256 rows; between points the error is interpolated linearly,
//!   beyond the end rows it holds (assumed); the control subtracts it from the position (the
//!   error is positive where the travel is too long); a table in `INCH` holds inches.
//!
//! Assumed: axes named X, Y, Z; the `BACKLASH` column holds the whole error moving negative.

use std::collections::BTreeMap;

use ballbar_model::Axis;

/// The compensation of a HEIDENHAIN's axes: per axis, rows of `(AXISPOS, error moving up,
/// error moving down)`, mm.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Heidenhain {
    tables: BTreeMap<Axis, Vec<(f64, f64, f64)>>,
}

/// A TNC table: its unit factor to mm, its column names and rows (the `DOC` column left out).
fn table(text: &str, name: &str) -> Result<(f64, Vec<String>, Vec<(usize, Vec<String>)>), String> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let (_, begin) = lines.next().ok_or_else(|| format!("{name}: empty"))?;
    let words: Vec<&str> = begin.split_whitespace().collect();
    if words.first() != Some(&"BEGIN") {
        return Err(format!("{name}:1: a table starts with BEGIN <name>"));
    }
    let unit = match words.get(2).copied() {
        None | Some("MM") => 1.0,
        Some("INCH") => 25.4,
        Some(u) => return Err(format!("{name}:1: unit '{u}' is neither MM nor INCH")),
    };
    let (_, header) = lines.next().ok_or_else(|| format!("{name}: no column names"))?;
    let columns: Vec<String> =
        header.split_whitespace().take_while(|c| *c != "DOC").map(str::to_string).collect();
    let mut rows = Vec::new();
    let mut ended = false;
    for (k, l) in lines {
        if l.trim() == "[END]" {
            ended = true;
            break;
        }
        let fields: Vec<String> =
            l.split_whitespace().take(columns.len()).map(str::to_string).collect();
        if fields.len() < columns.len() {
            return Err(format!("{name}:{}: {} columns expected", k + 1, columns.len()));
        }
        rows.push((k + 1, fields));
    }
    if !ended {
        return Err(format!("{name}: no [END]"));
    }
    Ok((unit, columns, rows))
}

fn axis_named(n: &str) -> Option<Axis> {
    match n {
        "X" => Some(Axis::X),
        "Y" => Some(Axis::Y),
        "Z" => Some(Axis::Z),
        _ => None,
    }
}

impl Heidenhain {
    /// Read the active assignment of a `.CMA` table (`cma`, named `cma_name`) and the tables it
    /// names (`read` gives a file's text by name).
    pub fn parse(
        cma: &str,
        cma_name: &str,
        read: &dyn Fn(&str) -> Result<String, String>,
    ) -> Result<Heidenhain, String> {
        let (_, columns, rows) = table(cma, cma_name)?;
        let active = columns
            .iter()
            .position(|c| c == "ACTIVE")
            .ok_or_else(|| format!("{cma_name}: no ACTIVE column"))?;
        let mut out = Heidenhain::default();
        // Rows without a `*` in ACTIVE have one column less when split at spaces: only the
        // active row is read, and it has every column.
        let Some((_, row)) = rows.iter().find(|(_, r)| r.get(active).is_some_and(|a| a == "*"))
        else {
            return Ok(out);
        };
        for (c, file) in columns.iter().zip(row) {
            let Some(axis) = axis_named(c) else { continue };
            let text = read(file).map_err(|m| format!("{cma_name}: {c}: {file}: {m}"))?;
            let (unit, cols, rows) = table(&text, file)?;
            let col = |n: &str| cols.iter().position(|c| c == n);
            let pos = col("AXISPOS").ok_or_else(|| format!("{file}: no AXISPOS column"))?;
            let up = col(c).ok_or_else(|| format!("{file}: no {c} column"))?;
            let down = col("BACKLASH");
            if rows.len() > 256 {
                return Err(format!("{file}: {} rows: a table holds at most 256", rows.len()));
            }
            let mut t: Vec<(f64, f64, f64)> = Vec::new();
            for (line, r) in &rows {
                let num = |k: usize| {
                    r[k].parse::<f64>()
                        .map(|v| v * unit)
                        .map_err(|_| format!("{file}:{line}: '{}' is not a number", r[k]))
                };
                let (q, u) = (num(pos)?, num(up)?);
                let d = down.map(num).transpose()?.unwrap_or(u);
                if t.last().is_some_and(|p| q <= p.0) {
                    return Err(format!(
                        "{file}:{line}: AXISPOS {q} is not above the previous row's"
                    ));
                }
                t.push((q, u, d));
            }
            if t.is_empty() {
                return Err(format!("{file}: no rows"));
            }
            out.tables.insert(axis, t);
        }
        Ok(out)
    }

    /// Whether `axis` is compensated.
    pub fn has(&self, axis: Axis) -> bool {
        self.tables.contains_key(&axis)
    }

    /// The span of `axis`'s table, its first and last `AXISPOS`, mm; `None` without one.
    pub fn span(&self, axis: Axis) -> Option<[f64; 2]> {
        self.tables.get(&axis).map(|t| [t[0].0, t[t.len() - 1].0])
    }

    /// What is added to the commanded position `q` of `axis` moving up or down, mm: minus the
    /// error the table states there.
    pub fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        let Some(t) = self.tables.get(&axis) else { return 0.0 };
        let v = |r: &(f64, f64, f64)| if forward { r.1 } else { r.2 };
        let error = if q <= t[0].0 {
            v(&t[0])
        } else if q >= t[t.len() - 1].0 {
            v(&t[t.len() - 1])
        } else {
            let k = t.iter().position(|r| r.0 > q).unwrap_or(t.len() - 1);
            let (a, b) = (&t[k - 1], &t[k]);
            v(a) + (v(b) - v(a)) * (q - a.0) / (b.0 - a.0)
        };
        -error
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_active_row_assigns_the_tables_and_the_error_is_subtracted_each_way() {
        let cma = "BEGIN CONFIG.CMA\nNR  X      Z      ACTIVE DOC\n0   A.COM  B.COM         old\n1   X.COM  B.COM  *      now\n[END]\n";
        let x = "BEGIN X.COM MM\nNR AXISPOS X BACKLASH DOC\n0 +0.0 +0.001 +0.003 the text\n1 +100.0 +0.011 +0.013\n[END]\n";
        let z = "BEGIN B.COM INCH\nNR AXISPOS Z\n0 0 0.001\n[END]\n";
        let h = Heidenhain::parse(cma, "CONFIG.CMA", &|n| match n {
            "X.COM" => Ok(x.into()),
            "B.COM" => Ok(z.into()),
            _ => Err("no such file".into()),
        })
        .unwrap();
        // Halfway: 6 µm moving up, 8 µm moving down; subtracted.
        assert!((h.trim(Axis::X, 50.0, true) + 0.006).abs() < 1e-15);
        assert!((h.trim(Axis::X, 50.0, false) + 0.008).abs() < 1e-15);
        // Beyond the ends: held.
        assert_eq!(h.trim(Axis::X, 500.0, true), -0.011);
        // Z's table is in inches, with no BACKLASH column: the same both ways.
        assert!((h.trim(Axis::Z, 7.0, false) + 0.0254).abs() < 1e-15);
        assert!(!h.has(Axis::Y));
    }

    #[test]
    fn a_bad_table_names_its_file_and_line() {
        let cma = "BEGIN C.CMA\nNR X ACTIVE\n0 X.COM *\n[END]\n";
        let bad = |x: &'static str| {
            Heidenhain::parse(cma, "C.CMA", &move |_| Ok(x.to_string())).unwrap_err()
        };
        assert!(bad("BEGIN X.COM MM\nNR AXISPOS X\n0 1 0\n1 1 0\n[END]\n").starts_with("X.COM:4:"));
        assert!(bad("BEGIN X.COM MM\nNR AXISPOS X\n0 1 0.0x\n[END]\n").starts_with("X.COM:3:"));
        assert!(bad("BEGIN X.COM MM\nNR AXISPOS X\n0 1 0\n").contains("[END]"));
    }
}
