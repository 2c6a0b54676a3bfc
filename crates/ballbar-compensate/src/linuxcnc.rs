//! LinuxCNC's joint compensation: the `[JOINT_n]` keys of its INI file (`BACKLASH`, `COMP_FILE`,
//! `COMP_FILE_TYPE`) and the compensation file, as LinuxCNC's own code reads and applies them.
//!
//! From LinuxCNC's source (`src/emc/motion/control.c`, `compute_screw_comp()` and
//! `output_to_hal()`; the loader `usrmotLoadComp()` in `src/emc/motion/usrmotintf.cc`, which sends
//! each entry to the motion module's `EMCMOT_SET_JOINT_COMP` in `src/emc/motion/command.c`):
//! - a compensation file is read line by line with `sscanf(line, "%lf %lf %lf")`: a line
//!   counts when it starts with three numbers (what follows them is not read); reading stops
//!   at the first line that does not (a blank line, a comment); at most 256 entries
//!   (`EMCMOT_COMP_SIZE`), the nominals strictly ascending;
//! - `COMP_FILE_TYPE = 1`: the two values are trims, `nominal - actual` (the position reached
//!   when the joint is commanded to `nominal`, moving that way); type 0: the positions reached;
//! - each servo cycle the trim of the joint's direction of motion (the sign of the commanded
//!   joint velocity `vel_cmd`; at rest the last trim is kept) is interpolated linearly between the
//!   entries around the commanded position, and held at the end entries' values outside them;
//!   it is added to the commanded joint position (`motor_pos_cmd = pos_cmd + backlash_filt +
//!   motor_offset`, `backlash_filt` the trim ramped at half the joint's velocity and
//!   acceleration limits);
//! - without a table, `BACKLASH = b` gives `+b/2` moving up and `-b/2` moving down; a joint with
//!   a table does not use `BACKLASH`, so the backlash goes into the table's two directions.
//!
//! Joints map to axes as the configuration says (`[KINS] KINEMATICS = trivkins coordinates=XYYZ`
//! makes joint `n` the `n`-th letter, a gantry's axis two joints; `[TRAJ] COORDINATES` where the
//! kinematics line gives none): [`Files::parse`] reads the layout of an existing INI file. The
//! written `linuxcnc.ini` holds only `[JOINT_n]` sections, to merge into the machine's INI file,
//! whose layout it does not restate.
//!
//! Units: mm (a linear joint in a metric configuration). This module only makes and reads the
//! text; files are written by the caller.

use std::collections::BTreeMap;

/// LinuxCNC's largest compensation table (`EMCMOT_COMP_SIZE`).
pub const MAX_ENTRIES: usize = 256;

/// Decimal places of a written nominal, mm: 1 nm.
const NOMINAL_DECIMALS: usize = 6;
/// Decimal places of a written trim, mm: 0.1 nm, the resolution the prediction takes for the
/// controller's (a trim is a double in LinuxCNC; the motor's own step is the machine's, not
/// known here).
pub const TRIM_DECIMALS: usize = 7;

/// The resolution of a written trim, mm ([`TRIM_DECIMALS`]).
pub const TRIM_RESOLUTION_MM: f64 = 1e-7;

/// One line of a compensation table, mm: the trims to add at `nominal` moving up and down.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    /// Commanded joint position.
    pub nominal: f64,
    /// Trim when moving in the positive direction, `nominal - actual`.
    pub forward: f64,
    /// Trim when moving in the negative direction.
    pub reverse: f64,
}

/// A compensation table LinuxCNC reads as intended: 1 to 256 entries of finite numbers, the
/// nominals strictly ascending.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    entries: Vec<Entry>,
}

impl Table {
    /// The table of these entries, or why LinuxCNC would misread it.
    pub fn new(entries: Vec<Entry>) -> Result<Table, String> {
        if entries.is_empty() {
            return Err("a compensation table needs at least one entry".into());
        }
        if entries.len() > MAX_ENTRIES {
            return Err(format!(
                "{} entries: LinuxCNC keeps at most {MAX_ENTRIES} per joint (EMCMOT_COMP_SIZE) and would drop the rest",
                entries.len()
            ));
        }
        for (k, e) in entries.iter().enumerate() {
            if !(e.nominal.is_finite() && e.forward.is_finite() && e.reverse.is_finite()) {
                return Err(format!("entry {}: not a finite number", k + 1));
            }
            if k > 0 && e.nominal <= entries[k - 1].nominal {
                return Err(format!(
                    "entry {}: nominal {} mm is not above the previous {} mm: LinuxCNC needs the nominals strictly ascending",
                    k + 1,
                    e.nominal,
                    entries[k - 1].nominal
                ));
            }
        }
        Ok(Table { entries })
    }

    /// The entries, ascending.
    pub fn entries(&self) -> &[Entry] {
        &self.entries
    }

    /// The trim at commanded position `q` moving up (`forward`) or down: linear between the
    /// entries around `q`, the end entries' values outside them.
    pub fn trim(&self, q: f64, forward: bool) -> f64 {
        let pick = |e: &Entry| if forward { e.forward } else { e.reverse };
        let first = &self.entries[0];
        let last = &self.entries[self.entries.len() - 1];
        if q <= first.nominal {
            return pick(first);
        }
        if q >= last.nominal {
            return pick(last);
        }
        let k = self.entries.partition_point(|e| e.nominal <= q);
        let (a, b) = (&self.entries[k - 1], &self.entries[k]);
        let f = (q - a.nominal) / (b.nominal - a.nominal);
        pick(a) + f * (pick(b) - pick(a))
    }

    /// The file's text: one line per entry, `nominal forward reverse`, nothing else.
    pub fn text(&self) -> String {
        let mut s = String::new();
        for e in &self.entries {
            s.push_str(&format!(
                "{:.n$} {:.t$} {:.t$}\n",
                e.nominal,
                e.forward,
                e.reverse,
                n = NOMINAL_DECIMALS,
                t = TRIM_DECIMALS
            ));
        }
        s
    }

    /// A compensation file's text read as LinuxCNC reads it (module docs): the lines up to the
    /// first that does not start with three numbers, with a note naming the first line not read
    /// when anything but blank lines follows it. The entries read must make a table LinuxCNC
    /// applies as intended (an error names the file and line otherwise). `kind` 0 gives
    /// positions reached, 1 trims.
    pub fn parse(text: &str, name: &str, kind: u32) -> Result<(Table, Option<String>), String> {
        let mut entries = Vec::new();
        let mut note = None;
        let lines: Vec<&str> = text.lines().collect();
        for (k, line) in lines.iter().enumerate() {
            let Some([nominal, a, b]) = three_numbers(line) else {
                if lines[k..].iter().any(|l| !l.trim().is_empty()) {
                    note = Some(format!(
                        "{name}:{}: '{}' is not three numbers: LinuxCNC stops reading the file there, so this line and the {} after it are not applied (nor read here)",
                        k + 1,
                        line.trim(),
                        lines.len() - k - 1
                    ));
                }
                break;
            };
            if !(nominal.is_finite() && a.is_finite() && b.is_finite()) {
                return Err(format!("{name}:{}: '{}': not a finite number", k + 1, line.trim()));
            }
            let (forward, reverse) = if kind == 0 { (nominal - a, nominal - b) } else { (a, b) };
            entries.push(Entry { nominal, forward, reverse });
        }
        if entries.is_empty() {
            return Err(format!(
                "{name}: no line LinuxCNC reads (the first line is not three numbers: nominal forward reverse, mm)"
            ));
        }
        let table = Table::new(entries).map_err(|m| format!("{name}: {m}"))?;
        Ok((table, note))
    }
}

/// The three numbers `sscanf(line, "%lf %lf %lf")` reads at the start of a line: each the
/// longest prefix of a whitespace-separated word that is a number (`strtod`), the next word
/// read only when the previous was whole.
fn three_numbers(line: &str) -> Option<[f64; 3]> {
    let mut out = [0.0; 3];
    let mut words = line.split_whitespace();
    for (k, slot) in out.iter_mut().enumerate() {
        let w = words.next()?;
        let (x, whole) = number_prefix(w)?;
        *slot = x;
        if !whole && k < 2 {
            return None;
        }
    }
    Some(out)
}

/// The longest prefix of `w` that is a number, and whether it is all of `w`.
fn number_prefix(w: &str) -> Option<(f64, bool)> {
    (1..=w.len())
        .rev()
        .filter(|&n| w.is_char_boundary(n))
        .find_map(|n| w[..n].parse::<f64>().ok().map(|x| (x, n == w.len())))
}

/// What LinuxCNC applies to one joint.
#[derive(Clone, Debug, PartialEq)]
pub enum Joint {
    /// `BACKLASH = b`, mm.
    Backlash(f64),
    /// `COMP_FILE` (its name) with `COMP_FILE_TYPE = 1`.
    Table {
        /// The file's name, beside the INI file.
        file: String,
        /// The table.
        table: Table,
    },
}

impl Joint {
    /// The trim LinuxCNC adds at commanded position `q` moving up (`forward`) or down, mm.
    pub fn trim(&self, q: f64, forward: bool) -> f64 {
        match self {
            Joint::Backlash(b) => {
                if forward {
                    0.5 * b
                } else {
                    -0.5 * b
                }
            }
            Joint::Table { table, .. } => table.trim(q, forward),
        }
    }
}

/// The compensation of a machine's joints, by joint number, and the configuration's joint
/// layout where an INI file states it.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Files {
    /// Joint number → what it applies.
    pub joints: BTreeMap<usize, Joint>,
    /// Axis letters of joints 0, 1, ... (`XYZ`; `XYYZ` for a gantry on Y; `-` for a joint whose
    /// axis is not known).
    pub coordinates: String,
    /// Where [`Files::coordinates`] was read (`[KINS] KINEMATICS coordinates=`, `[TRAJ]
    /// COORDINATES`), or `None` when the file states no layout (trivkins' default order
    /// `XYZABCUVW` is then in `coordinates`).
    pub layout: Option<String>,
    /// The kinematics module the INI file names (`[KINS] KINEMATICS`, its first word).
    pub kinematics: Option<String>,
    /// What LinuxCNC would not read of the files (lines after the first that is not three
    /// numbers), one note per file.
    pub notes: Vec<String>,
}

/// The name of joint `n`'s compensation file.
pub fn comp_file_name(n: usize) -> String {
    format!("joint-{n}.comp")
}

/// trivkins' joint order without `coordinates=`.
const TRIVKINS_DEFAULT: &str = "XYZABCUVW";

impl Files {
    /// The INI file: one `[JOINT_n]` section per compensated joint, nothing else (the sections
    /// are merged into the machine's INI file, whose kinematics and joint count stay its own).
    pub fn ini_text(&self) -> String {
        let mut s = String::from(
            "# Joint compensation from a ballbar test (ballbar compensate). Merge these sections into the\n\
             # machine's INI file; lengths in mm. A joint with a COMP_FILE takes its backlash from the file.\n",
        );
        for (n, j) in &self.joints {
            s.push_str(&format!("\n[JOINT_{n}]\n"));
            match j {
                Joint::Backlash(b) => {
                    s.push_str(&format!("BACKLASH = {b:.t$}\n", t = TRIM_DECIMALS))
                }
                Joint::Table { file, .. } => {
                    s.push_str(&format!("COMP_FILE = {file}\nCOMP_FILE_TYPE = 1\n"))
                }
            }
        }
        s
    }

    /// Every file to write: `linuxcnc.ini` and each joint's table, `(name, text)`.
    pub fn texts(&self) -> Vec<(String, String)> {
        let mut out = vec![("linuxcnc.ini".to_string(), self.ini_text())];
        for j in self.joints.values() {
            if let Joint::Table { file, table } = j {
                out.push((file.clone(), table.text()));
            }
        }
        out
    }

    /// The joint number of an axis letter (the first, for a gantry's).
    pub fn joint_of(&self, axis: char) -> Option<usize> {
        self.coordinates.chars().position(|c| c == axis)
    }

    /// The joint numbers of an axis letter (two or more: a gantry).
    pub fn joints_of(&self, axis: char) -> Vec<usize> {
        self.coordinates.char_indices().filter(|(_, c)| *c == axis).map(|(k, _)| k).collect()
    }

    /// An INI file's joint compensation: `[JOINT_n]` sections' `BACKLASH`, `COMP_FILE`,
    /// `COMP_FILE_TYPE` (other sections and keys are the machine's, ignored), read strictly (a
    /// bad number names its line); the joint layout from `[KINS] KINEMATICS = ...
    /// coordinates=...`, else `[TRAJ] COORDINATES` (trivkins' default `XYZABCUVW` without
    /// either). A compensation file is read as LinuxCNC reads it ([`Table::parse`]). `read`
    /// gives a named compensation file's text.
    pub fn parse(
        ini: &str,
        ini_name: &str,
        read: &dyn Fn(&str) -> Result<String, String>,
    ) -> Result<Files, String> {
        let mut section = String::new();
        let mut keys: BTreeMap<usize, BTreeMap<String, (String, usize)>> = BTreeMap::new();
        let mut kins_coordinates: Option<(String, usize)> = None;
        let mut traj_coordinates: Option<(String, usize)> = None;
        let mut kinematics = None;
        for (k, raw) in ini.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') || line.starts_with(';') {
                continue;
            }
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                section = name.trim().to_string();
                continue;
            }
            let Some((key, value)) = line.split_once('=') else { continue };
            let (key, value) = (key.trim().to_string(), value.trim().to_string());
            if section == "KINS" && key == "KINEMATICS" {
                kinematics = value.split_whitespace().next().map(str::to_string);
                if let Some(c) =
                    value.split_whitespace().find_map(|w| w.strip_prefix("coordinates="))
                {
                    kins_coordinates = Some((c.to_uppercase(), k + 1));
                }
            }
            if section == "TRAJ" && key == "COORDINATES" {
                let letters: String = value.split_whitespace().collect::<String>().to_uppercase();
                traj_coordinates = Some((letters, k + 1));
            }
            if let Some(n) = section.strip_prefix("JOINT_") {
                let n: usize = n.parse().map_err(|_| {
                    format!("{ini_name}:{}: section [{section}] is not [JOINT_<number>]", k + 1)
                })?;
                keys.entry(n).or_default().insert(key, (value, k + 1));
            }
        }
        let (coordinates, layout) = match (kins_coordinates, traj_coordinates) {
            (Some((c, line)), _) => {
                (c.clone(), Some(format!("{ini_name}:{line}: [KINS] KINEMATICS coordinates={c}")))
            }
            (None, Some((c, line))) => {
                (c.clone(), Some(format!("{ini_name}:{line}: [TRAJ] COORDINATES = {c}")))
            }
            (None, None) => (TRIVKINS_DEFAULT.to_string(), None),
        };
        if let Some(bad) = coordinates.chars().find(|c| !TRIVKINS_DEFAULT.contains(*c)) {
            return Err(format!(
                "{}: '{bad}' is not an axis letter (X Y Z A B C U V W)",
                layout.clone().unwrap_or_default()
            ));
        }
        let mut joints = BTreeMap::new();
        let mut notes = Vec::new();
        for (n, kv) in keys {
            let number = |key: &str| -> Result<Option<f64>, String> {
                kv.get(key)
                    .map(|(v, line)| {
                        v.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                            format!("{ini_name}:{line}: [JOINT_{n}] {key} = {v} is not a number")
                        })
                    })
                    .transpose()
            };
            if let Some((file, line)) = kv.get("COMP_FILE") {
                let kind = number("COMP_FILE_TYPE")?.unwrap_or(0.0);
                if kind != 0.0 && kind != 1.0 {
                    return Err(format!(
                        "{ini_name}: [JOINT_{n}] COMP_FILE_TYPE = {kind}: LinuxCNC knows 0 (positions) and 1 (trims)"
                    ));
                }
                let text =
                    read(file).map_err(|m| format!("{ini_name}:{line}: COMP_FILE {file}: {m}"))?;
                let (table, note) = Table::parse(&text, file, kind as u32)?;
                notes.extend(note);
                joints.insert(n, Joint::Table { file: file.clone(), table });
            } else if let Some(b) = number("BACKLASH")? {
                joints.insert(n, Joint::Backlash(b));
            }
        }
        Ok(Files { joints, coordinates, layout, kinematics, notes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn e(nominal: f64, forward: f64, reverse: f64) -> Entry {
        Entry { nominal, forward, reverse }
    }

    #[test]
    fn a_table_interpolates_between_nominals_and_holds_outside_in_each_direction() {
        let t = Table::new(vec![e(0.0, 0.001, -0.001), e(100.0, 0.003, 0.002)]).unwrap();
        // Halfway: the mean of the two entries of that direction.
        assert!((t.trim(50.0, true) - 0.002).abs() < 1e-15);
        assert!((t.trim(50.0, false) - 0.0005).abs() < 1e-15);
        // A quarter of the way.
        assert!((t.trim(25.0, true) - 0.0015).abs() < 1e-15);
        // Outside: the end values, held.
        assert_eq!(t.trim(-50.0, true), 0.001);
        assert_eq!(t.trim(500.0, false), 0.002);
        // On a nominal: its value.
        assert_eq!(t.trim(100.0, true), 0.003);
        // BACKLASH b: +b/2 up, -b/2 down.
        assert_eq!(Joint::Backlash(0.004).trim(3.0, true), 0.002);
        assert_eq!(Joint::Backlash(0.004).trim(3.0, false), -0.002);
    }

    #[test]
    fn a_table_linuxcnc_would_misread_is_refused() {
        // More than 256 entries.
        let many: Vec<Entry> = (0..257).map(|k| e(k as f64, 0.0, 0.0)).collect();
        let m = Table::new(many).unwrap_err();
        assert!(m.contains("257 entries") && m.contains("256"), "{m}");
        // Descending, and a repeated nominal.
        let m = Table::new(vec![e(10.0, 0.0, 0.0), e(5.0, 0.0, 0.0)]).unwrap_err();
        assert!(m.contains("entry 2") && m.contains("ascending"), "{m}");
        assert!(Table::new(vec![e(10.0, 0.0, 0.0), e(10.0, 0.0, 0.0)]).is_err());
        // Not finite, and empty.
        assert!(Table::new(vec![e(0.0, f64::NAN, 0.0)]).is_err());
        assert!(Table::new(vec![]).is_err());
        // What LinuxCNC reads: up to the first line that is not three numbers. A comment line
        // ends the table there (noted, with the line), a blank line at the end says nothing,
        // text after the third number is not read, a word in place of a number ends it.
        let (t, note) = Table::parse("0 0 0\n# pitch\n10 0 0\n", "j.comp", 1).unwrap();
        assert_eq!(t.entries().len(), 1);
        let note = note.unwrap();
        assert!(note.starts_with("j.comp:2:") && note.contains("# pitch"), "{note}");
        let (t, note) = Table::parse("0 0 0\n10 0.001 0.002\n\n", "j.comp", 1).unwrap();
        assert_eq!((t.entries().len(), note), (2, None));
        let (t, note) = Table::parse("0 0 0 ; zero\n10 0.001 x\n", "j.comp", 1).unwrap();
        assert_eq!(t.entries().len(), 1);
        assert!(note.unwrap().starts_with("j.comp:2:"));
        let (t, _) = Table::parse("10 0.001 0.002mm\n", "j.comp", 1).unwrap();
        assert_eq!(t.entries()[0].reverse, 0.002);
        // Nothing LinuxCNC reads, or entries it would misapply: refused.
        assert!(Table::parse("0 0\n", "j.comp", 1).unwrap_err().contains("no line"));
        assert!(Table::parse("\n0 0 0\n", "j.comp", 1).is_err());
        let m = Table::parse("10 0 0\n5 0 0\n", "j.comp", 1).unwrap_err();
        assert!(m.contains("ascending"), "{m}");
    }

    #[test]
    fn the_written_text_is_three_numbers_a_line_and_reads_back_within_its_resolution() {
        let t = Table::new(vec![e(150.0, 0.00123456789, -0.0019), e(450.5, -0.004, 0.0)]).unwrap();
        let text = t.text();
        assert_eq!(text, "150.000000 0.0012346 -0.0019000\n450.500000 -0.0040000 0.0000000\n");
        let (back, _) = Table::parse(&text, "j", 1).unwrap();
        for (a, b) in back.entries().iter().zip(t.entries()) {
            assert!((a.forward - b.forward).abs() <= TRIM_RESOLUTION_MM / 2.0 + 1e-15);
            assert_eq!(a.nominal, b.nominal);
        }
        // Type 0 (positions reached): trims are nominal minus them.
        let (p, _) = Table::parse("100 99.998 100.001\n", "j", 0).unwrap();
        assert!((p.entries()[0].forward - 0.002).abs() < 1e-12);
        assert!((p.entries()[0].reverse + 0.001).abs() < 1e-12);
    }

    #[test]
    fn an_ini_file_round_trips_and_holds_only_joint_sections() {
        let table = Table::new(vec![e(0.0, 0.001, -0.001), e(10.0, 0.0, -0.002)]).unwrap();
        let mut files = Files { coordinates: "XYZ".into(), ..Files::default() };
        files.joints.insert(0, Joint::Table { file: comp_file_name(0), table: table.clone() });
        files.joints.insert(2, Joint::Backlash(0.0032));
        let texts = files.texts();
        assert_eq!(texts.len(), 2);
        let ini = &texts[0].1;
        assert!(ini.contains("[JOINT_0]\nCOMP_FILE = joint-0.comp\nCOMP_FILE_TYPE = 1\n"), "{ini}");
        assert!(ini.contains("[JOINT_2]\nBACKLASH = 0.0032000\n"), "{ini}");
        assert!(!ini.contains("[JOINT_1]"));
        // Merged into the machine's INI file: no section but the joints' (a [KINS] would
        // replace the machine's kinematics and joint count).
        let sections: Vec<&str> = ini.lines().filter(|l| l.starts_with('[')).collect();
        assert_eq!(sections, ["[JOINT_0]", "[JOINT_2]"], "{ini}");
        let comp = texts[1].1.clone();
        let back = Files::parse(ini, "linuxcnc.ini", &|name| {
            if name == "joint-0.comp" { Ok(comp.clone()) } else { Err("no such file".into()) }
        })
        .unwrap();
        assert_eq!(back.joints, files.joints);
        // No layout stated: trivkins' default order.
        assert_eq!((back.layout.as_deref(), back.joint_of('Z')), (None, Some(2)));
        // A bad number names its line.
        let m = Files::parse("[JOINT_1]\nBACKLASH = 0.01mm\n", "m.ini", &|_| Err(String::new()))
            .unwrap_err();
        assert!(m.starts_with("m.ini:2:"), "{m}");
    }

    #[test]
    fn an_ini_files_joint_layout_is_read_from_its_kinematics_or_its_coordinates() {
        let none = |_: &str| Err(String::new());
        // A gantry: Y on joints 1 and 2.
        let f = Files::parse(
            "[KINS]\nJOINTS = 4\nKINEMATICS = trivkins coordinates=xyyz kinstype=BOTH\n",
            "g.ini",
            &none,
        )
        .unwrap();
        assert_eq!(
            (f.coordinates.as_str(), f.joints_of('Y'), f.joint_of('Z')),
            ("XYYZ", vec![1, 2], Some(3))
        );
        assert!(f.layout.unwrap().starts_with("g.ini:3: [KINS] KINEMATICS coordinates=XYYZ"));
        assert_eq!(f.kinematics.as_deref(), Some("trivkins"));
        // [TRAJ] COORDINATES where the kinematics line names none: a lathe's X and Z.
        let f = Files::parse("[TRAJ]\nCOORDINATES = X Z\n", "l.ini", &none).unwrap();
        assert_eq!((f.joint_of('X'), f.joint_of('Z'), f.joint_of('Y')), (Some(0), Some(1), None));
        // Not an axis letter.
        assert!(Files::parse("[TRAJ]\nCOORDINATES = X Q\n", "l.ini", &none).is_err());
    }
}
