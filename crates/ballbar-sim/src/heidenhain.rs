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
//! - the assignment is `[axis of the .COM's column] = F(axis of the .CMA's column in which the
//!   .COM is entered)` (the manual's "Assigning the compensation value tables to the axes",
//!   with its example of axis sag, `Z = F(Y)`): a table entered in the `.CMA`'s `X` column has
//!   `AXISPOS` in X, its `X` column is X's own error (`X = F(X)`), and a `Y` column is Y's
//!   error as a function of X's position (`Y = F(X)`), interpolated as the axis's own and
//!   subtracted from Y's position.
//!
//! Assumed: axes named X, Y, Z; the `BACKLASH` column holds the whole error moving negative of
//! the axis the table is entered for (its own column), and a column of another axis holds the
//! same value whichever way either axis moves.

use std::collections::BTreeMap;

use ballbar_model::Axis;

/// The compensation of a HEIDENHAIN's axes: per axis, rows of `(AXISPOS, error moving up,
/// error moving down)`, mm.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Heidenhain {
    tables: BTreeMap<Axis, Vec<(f64, f64, f64)>>,
    /// `(input, output, rows of (input's AXISPOS, output's error))`, mm.
    cross: Vec<(Axis, Axis, Vec<(f64, f64)>)>,
}

/// Linear between rows `(position, value)`, the end rows' values beyond them.
fn interpolate(rows: &[(f64, f64)], q: f64) -> f64 {
    if q <= rows[0].0 {
        return rows[0].1;
    }
    if q >= rows[rows.len() - 1].0 {
        return rows[rows.len() - 1].1;
    }
    let k = rows.iter().position(|r| r.0 > q).unwrap_or(rows.len() - 1);
    let (a, b) = (rows[k - 1], rows[k]);
    a.1 + (b.1 - a.1) * (q - a.0) / (b.0 - a.0)
}

/// A TNC table: its unit factor to mm, its column names and rows (the `DOC` column left out).
/// A table's unit (mm per unit), the line of its column names and the names, and its rows
/// with their lines.
type Parsed = (f64, usize, Vec<String>, Vec<(usize, Vec<String>)>);

fn table(text: &str, name: &str) -> Result<Parsed, String> {
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
    let (h, header) = lines.next().ok_or_else(|| format!("{name}: no column names"))?;
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
    Ok((unit, h + 1, columns, rows))
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
        let (_, _, columns, rows) = table(cma, cma_name)?;
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
            let Some(axis) = axis_named(c) else {
                if ["NR", "ACTIVE", "DOC"].contains(&c.as_str()) {
                    continue;
                }
                // A rotary axis's table, or a column this emulation does not know: refused
                // rather than left out of what it applies (and of what `--existing` keeps).
                return Err(format!(
                    "{cma_name}: column {c} of the active row assigns {file}: only the linear axes X, Y, Z are read here"
                ));
            };
            let text = read(file).map_err(|m| format!("{cma_name}: {c}: {file}: {m}"))?;
            let (unit, header, cols, rows) = table(&text, file)?;
            let col = |n: &str| cols.iter().position(|c| c == n);
            let pos =
                col("AXISPOS").ok_or_else(|| format!("{file}:{header}: no AXISPOS column"))?;
            if let Some(c) = cols.iter().find(|c| {
                axis_named(c).is_none()
                    && !["NR", "AXISPOS", "BACKLASH", "DOC"].contains(&c.as_str())
            }) {
                return Err(format!(
                    "{file}:{header}: column {c}: only the columns NR, AXISPOS, X, Y, Z, BACKLASH and DOC are read here"
                ));
            }
            // The axes' columns: each the error of that axis as a function of this one.
            let outputs: Vec<(Axis, usize)> = cols
                .iter()
                .enumerate()
                .filter_map(|(k, n)| axis_named(n).map(|a| (a, k)))
                .collect();
            if outputs.is_empty() {
                return Err(format!("{file}:{header}: no column of an axis (X, Y, Z)"));
            }
            let down = col("BACKLASH");
            if down.is_some() && !outputs.iter().any(|o| o.0 == axis) {
                return Err(format!(
                    "{file}:{header}: a BACKLASH column without the column of its axis {axis}, to which it belongs"
                ));
            }
            if rows.len() > 256 {
                return Err(format!("{file}: {} rows: a table holds at most 256", rows.len()));
            }
            let mut positions: Vec<f64> = Vec::new();
            let mut values: Vec<Vec<f64>> = vec![Vec::new(); outputs.len()];
            let mut backlash: Vec<Option<f64>> = Vec::new();
            for (line, r) in &rows {
                let num = |k: usize| {
                    r[k].parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .map(|v| v * unit)
                        .ok_or_else(|| format!("{file}:{line}: '{}' is not a number", r[k]))
                };
                let q = num(pos)?;
                if positions.last().is_some_and(|p| q <= *p) {
                    return Err(format!(
                        "{file}:{line}: AXISPOS {q} is not above the previous row's"
                    ));
                }
                positions.push(q);
                for (v, (_, k)) in values.iter_mut().zip(&outputs) {
                    v.push(num(*k)?);
                }
                backlash.push(down.map(num).transpose()?);
            }
            if positions.is_empty() {
                return Err(format!("{file}: no rows"));
            }
            for ((output, _), v) in outputs.iter().zip(values) {
                if *output == axis {
                    let t = positions
                        .iter()
                        .zip(&v)
                        .zip(&backlash)
                        .map(|((&q, &u), d)| (q, u, d.unwrap_or(u)))
                        .collect();
                    out.tables.insert(axis, t);
                } else {
                    let rows = positions.iter().copied().zip(v).collect();
                    out.cross.push((axis, *output, rows));
                }
            }
        }
        Ok(out)
    }

    /// Whether `axis` is compensated (by its own table or another axis's column of it).
    pub fn has(&self, axis: Axis) -> bool {
        self.tables.contains_key(&axis) || self.cross.iter().any(|c| c.1 == axis)
    }

    /// The cross-axis columns, `(input, output, span of the input's AXISPOS)`, mm.
    pub fn cross_tables(&self) -> Vec<(Axis, Axis, [f64; 2])> {
        self.cross.iter().map(|(i, o, r)| (*i, *o, [r[0].0, r[r.len() - 1].0])).collect()
    }

    /// What the columns of `output` in `input`'s table add to `output`'s position at `input`'s
    /// position `q`, mm: minus the error they state there.
    pub fn cross_of(&self, input: Axis, output: Axis, q: f64) -> f64 {
        -self
            .cross
            .iter()
            .filter(|c| c.0 == input && c.1 == output)
            .map(|c| interpolate(&c.2, q))
            .sum::<f64>()
    }

    /// What the cross-axis columns add to the position of `output`, mm, at the commanded
    /// positions `commanded[axis.index()]` of every axis.
    pub fn cross(&self, output: Axis, commanded: &[f64; 6]) -> f64 {
        Axis::LINEAR.into_iter().map(|i| self.cross_of(i, output, commanded[i.index()])).sum()
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

    /// The manual's sag example: a table entered in the `.CMA`'s Y column with a `Z` column is
    /// Z's error as a function of Y, subtracted from Z, the same both ways.
    #[test]
    fn a_column_of_another_axis_is_that_axis_as_a_function_of_the_tables_axis() {
        let cma = "BEGIN CONFIG.CMA\nNR Y Z ACTIVE\n0 YS.COM Z.COM *\n[END]\n";
        let ys = "BEGIN YS.COM MM\nNR AXISPOS Y Z BACKLASH\n0 -90 0 0.010 0.002\n1 110 0.004 0.030 0.006\n[END]\n";
        let z = "BEGIN Z.COM MM\nNR AXISPOS Z\n0 0 0.001\n[END]\n";
        let h = Heidenhain::parse(cma, "CONFIG.CMA", &|n| match n {
            "YS.COM" => Ok(ys.into()),
            "Z.COM" => Ok(z.into()),
            _ => Err("no such file".into()),
        })
        .unwrap();
        // At Y = 10 mm, halfway: Z's error 0.020 mm, subtracted from Z; Y's own 2 µm moving
        // up, 4 µm moving down (the BACKLASH column is Y's).
        let mut at = [0.0; 6];
        at[Axis::Y.index()] = 10.0;
        at[Axis::X.index()] = 500.0;
        assert!((h.cross(Axis::Z, &at) + 0.020).abs() < 1e-15);
        assert!((h.cross_of(Axis::Y, Axis::Z, 10.0) + 0.020).abs() < 1e-15);
        assert_eq!(h.cross(Axis::X, &at), 0.0);
        assert!((h.trim(Axis::Y, 10.0, true) + 0.002).abs() < 1e-15);
        assert!((h.trim(Axis::Y, 10.0, false) + 0.004).abs() < 1e-15);
        // Z's own table is apart from it; beyond the rows the end values hold.
        assert!((h.trim(Axis::Z, 10.0, true) + 0.001).abs() < 1e-15);
        at[Axis::Y.index()] = 500.0;
        assert!((h.cross(Axis::Z, &at) + 0.030).abs() < 1e-15);
        assert_eq!(h.cross_tables(), vec![(Axis::Y, Axis::Z, [-90.0, 110.0])]);
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
        // Not a number the control could hold: a NaN or an infinity, in any cell.
        assert!(bad("BEGIN X.COM MM\nNR AXISPOS X\n0 nan 0\n[END]\n").starts_with("X.COM:3:"));
        assert!(bad("BEGIN X.COM MM\nNR AXISPOS X\n0 1 inf\n[END]\n").starts_with("X.COM:3:"));
        // What this reader does not apply is refused, never left out: a column it does not
        // know, a BACKLASH without its axis's column.
        let m = bad("BEGIN X.COM MM\nNR AXISPOS X A\n0 1 0 0\n[END]\n");
        assert!(m.starts_with("X.COM:2: column A"), "{m}");
        let m = bad("BEGIN X.COM MM\nNR AXISPOS Y BACKLASH\n0 1 0 0\n[END]\n");
        assert!(m.starts_with("X.COM:2:") && m.contains("BACKLASH"), "{m}");
    }

    #[test]
    fn a_rotary_axis_assigned_in_the_active_row_is_refused() {
        let cma = "BEGIN C.CMA\nNR X C ACTIVE\n0 X.COM C.COM *\n[END]\n";
        let x = "BEGIN X.COM MM\nNR AXISPOS X\n0 1 0\n[END]\n";
        let m = Heidenhain::parse(cma, "C.CMA", &|_| Ok(x.to_string())).unwrap_err();
        assert!(m.starts_with("C.CMA: column C") && m.contains("C.COM"), "{m}");
    }
}
