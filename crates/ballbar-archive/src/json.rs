//! The JSON messages and their JSON schemas, and the exact unit conversions.
//!
//! Numbers go through `serde_json`, which writes the shortest decimal that reads back to the
//! same `f64` and (with its `float_roundtrip` feature, enabled by this crate) reads decimals
//! correctly rounded: an `f64` survives the trip bit for bit.

use serde::{Deserialize, Serialize};

/// Schema names and JSON schemas (encoding `jsonschema`).
pub(crate) const RUN_HEADER_SCHEMA: (&str, &str) = (
    "ballbar.RunHeader",
    r#"{"title":"ballbar.RunHeader","description":"The header of one ballbar run (run CSV version 1)","type":"object","properties":{"index":{"type":"integer","description":"position of the run in the session"},"name":{"type":"string"},"file_name":{"type":"string","description":"the original file name"},"source":{"type":"string","description":"the path the run was read from"},"format_version":{"type":"integer"},"machine":{"type":["string","null"]},"plane":{"type":"string","enum":["XY","YZ","ZX","free"]},"direction":{"type":["string","null"],"enum":["CW","CCW",null]},"radius_mm":{"type":"number"},"feed_mm_per_min":{"type":"number"},"pivot_mm":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3},"table_ball_mm":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3},"tool_ball_mm":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3},"defaulted":{"type":"array","items":{"type":"string","enum":["table_ball_mm","tool_ball_mm"]},"description":"ball-position keys the run did not give, taken as 0,0,0 (absent: both given)"},"started_at":{"type":"string","description":"ISO 8601, as written in the run file"},"started_at_unix_s":{"type":"number"},"run_id":{"type":["string","null"]},"extra":{"type":"array","items":{"type":"array","items":{"type":"string"},"minItems":2,"maxItems":2},"description":"header keys of the run file that version 1 does not know, in order"},"columns":{"type":"array","items":{"type":"string"},"description":"axis columns present"},"samples":{"type":"integer"},"first_line":{"type":"integer","description":"line of the first sample in the source file"},"lines":{"type":"array","items":{"type":"integer"},"description":"line of each sample, when not consecutive"}},"required":["index","name","file_name","source","format_version","plane","radius_mm","feed_mm_per_min","pivot_mm","table_ball_mm","tool_ball_mm","started_at","started_at_unix_s","extra","columns","samples","first_line"]}"#,
);
pub(crate) const SAMPLE_SCHEMA: (&str, &str) = (
    "ballbar.Sample",
    r#"{"title":"ballbar.Sample","description":"One ballbar sample: commanded axis coordinates and the bar length deviation","type":"object","properties":{"t_s":{"type":"number","description":"seconds since started_at"},"x_mm":{"type":"number"},"y_mm":{"type":"number"},"z_mm":{"type":"number"},"a_deg":{"type":"number"},"b_deg":{"type":"number"},"c_deg":{"type":"number"},"dr_um":{"type":"number","description":"measured bar length minus nominal, µm"},"a_rad":{"type":"number","description":"exact internal value, present only where a_deg does not convert back exactly"},"b_rad":{"type":"number","description":"exact internal value, present only where b_deg does not convert back exactly"},"c_rad":{"type":"number","description":"exact internal value, present only where c_deg does not convert back exactly"},"dr_mm":{"type":"number","description":"exact internal value, present only where dr_um does not convert back exactly"}},"required":["t_s","dr_um"]}"#,
);
pub(crate) const MACHINE_SCHEMA: (&str, &str) = (
    "ballbar.Machine",
    r#"{"title":"ballbar.Machine","description":"The machine description the session was fitted with","type":"object","properties":{"spec":{"type":"object","description":"ballbar_model::MachineSpec"},"options":{"type":"object","description":"ballbar_model::ModelOptions"},"plugin_name":{"type":"string"},"plugin_version":{"type":"string"},"machine_file":{"type":["object","null"],"properties":{"name":{"type":"string"},"text":{"type":"string"}}}},"required":["spec","options","plugin_name","plugin_version"]}"#,
);
pub(crate) const FIT_SCHEMA: (&str, &str) = (
    "ballbar.FitParameters",
    r#"{"title":"ballbar.FitParameters","description":"Fitted parameters (internal units mm, rad, s; display unit and factor given), identifiability and residual statistics","type":"object","properties":{"parameters":{"type":"array","items":{"type":"object","properties":{"id":{"type":"string"},"label":{"type":"string"},"unit":{"type":"string"},"display_factor":{"type":"number"},"class":{"type":"string"},"nuisance":{"type":"boolean"},"value":{"type":["number","string"]},"std_uncertainty":{"type":["number","string"]},"estimable":{"type":"boolean"}}}},"n_machine":{"type":"integer"},"rank":{"type":"integer"},"condition_number":{"type":["number","string"]},"sigma_mm":{"type":["number","string"]},"dof":{"type":"integer"},"rho":{"type":["number","string"]},"inflation":{"type":["number","string"]},"n_samples":{"type":"integer"},"singular_values":{"type":"array","items":{"type":["number","string"]}},"null_space":{"type":"array","items":{"type":"object","properties":{"text":{"type":"string"},"components":{"type":"array","items":{"type":"object","properties":{"id":{"type":"string"},"amount":{"type":["number","string"]},"unit":{"type":"string"}}}}}}}},"required":["parameters","rank","condition_number","sigma_mm","dof","rho","null_space"]}"#,
);
pub(crate) const RESIDUAL_SCHEMA: (&str, &str) = (
    "ballbar.Residual",
    r#"{"title":"ballbar.Residual","description":"Fit residual (reading minus model) of one sample","type":"object","properties":{"t_s":{"type":"number","description":"seconds since the run's started_at"},"residual_um":{"type":"number"},"residual_mm":{"type":"number","description":"exact internal value, present only where residual_um does not convert back exactly"}},"required":["t_s","residual_um"]}"#,
);
pub(crate) const DIAGNOSIS_SCHEMA: (&str, &str) = (
    "ballbar.Diagnosis",
    r#"{"title":"ballbar.Diagnosis","description":"The diagnosis report, as the diagnose command writes it with --json"}"#,
);

/// The run header message.
#[derive(Serialize, Deserialize)]
pub(crate) struct HeaderMsg {
    pub index: usize,
    pub name: String,
    pub file_name: String,
    pub source: String,
    pub format_version: u32,
    pub machine: Option<String>,
    pub plane: String,
    pub direction: Option<String>,
    pub radius_mm: f64,
    pub feed_mm_per_min: f64,
    pub pivot_mm: [f64; 3],
    pub table_ball_mm: [f64; 3],
    pub tool_ball_mm: [f64; 3],
    /// The ball-position keys the run did not give (taken as 0, 0, 0); absent in archives
    /// written before the field existed, which read as given.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub defaulted: Vec<String>,
    pub started_at: String,
    pub started_at_unix_s: f64,
    pub run_id: Option<String>,
    pub extra: Vec<(String, String)>,
    pub columns: Vec<String>,
    pub samples: usize,
    pub first_line: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lines: Option<Vec<u32>>,
}

/// One sample message. Display units; the `*_rad`/`dr_mm` fields only where needed.
#[derive(Serialize, Deserialize, Default)]
pub(crate) struct SampleMsg {
    pub t_s: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub x_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub y_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub a_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub c_deg: Option<f64>,
    pub dr_um: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub a_rad: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b_rad: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub c_rad: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dr_mm: Option<f64>,
}

impl SampleMsg {
    /// The display value of axis `i` (X, Y, Z, A, B, C order).
    pub fn axis_mut(&mut self, i: usize) -> &mut Option<f64> {
        match i {
            0 => &mut self.x_mm,
            1 => &mut self.y_mm,
            2 => &mut self.z_mm,
            3 => &mut self.a_deg,
            4 => &mut self.b_deg,
            _ => &mut self.c_deg,
        }
    }

    /// The exact radian value of rotary axis `i` (3, 4, 5).
    pub fn exact_mut(&mut self, i: usize) -> &mut Option<f64> {
        match i {
            3 => &mut self.a_rad,
            4 => &mut self.b_rad,
            _ => &mut self.c_rad,
        }
    }
}

/// One residual message.
#[derive(Serialize, Deserialize)]
pub(crate) struct ResidualMsg {
    pub t_s: f64,
    pub residual_um: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_mm: Option<f64>,
}

/// Degrees to radians exactly as the run-CSV reader converts them (`ballbar_io::csv`).
pub(crate) fn deg_to_rad(v: f64) -> f64 {
    v.to_radians()
}

/// Radians to degrees as the run-CSV writer converts them.
pub(crate) fn rad_to_deg(v: f64) -> f64 {
    v.to_degrees()
}

/// µm to mm exactly as the run-CSV reader converts `dR_um`.
pub(crate) fn um_to_mm(v: f64) -> f64 {
    v * 1e-3
}

/// mm to µm as the run-CSV writer converts `dR_um`.
pub(crate) fn mm_to_um(v: f64) -> f64 {
    v * 1e3
}

/// Finds display values that convert back exactly; keeps a buffer for formatting.
#[derive(Default)]
pub(crate) struct Displayer {
    buf: String,
}

/// How many floats either side of the first guess are tried.
const NEIGHBOURS: usize = 4;

/// A shortest decimal is at most this long in `{:e}` form to be taken without looking further
/// (an 8-digit mantissa: what run files hold).
const SHORT: usize = 14;

impl Displayer {
    /// Length of the shortest round-trip decimal of `v` in exponent form.
    fn len(&mut self, v: f64) -> usize {
        use std::fmt::Write as _;
        self.buf.clear();
        let _ = write!(self.buf, "{v:e}");
        self.buf.len()
    }

    /// A display value `d` with `to_internal(d)` equal to `x` bit for bit, the one with the
    /// shortest decimal among `to_display(x)` and its neighbours; `None` if none converts back
    /// exactly. `x` must be finite.
    pub fn display(
        &mut self,
        x: f64,
        to_display: fn(f64) -> f64,
        to_internal: fn(f64) -> f64,
    ) -> Option<f64> {
        let exact = |d: f64| d.is_finite() && to_internal(d).to_bits() == x.to_bits();
        let d0 = to_display(x);
        if !d0.is_finite() {
            return None;
        }
        let mut best: Option<(usize, f64)> = None;
        if exact(d0) {
            let len = self.len(d0);
            if len <= SHORT {
                return Some(d0);
            }
            best = Some((len, d0));
        }
        let (mut up, mut down) = (d0, d0);
        for _ in 0..NEIGHBOURS {
            up = up.next_up();
            down = down.next_down();
            for d in [up, down] {
                if exact(d) {
                    let len = self.len(d);
                    if best.is_none_or(|(l, _)| len < l) {
                        best = Some((len, d));
                    }
                }
            }
        }
        best.map(|(_, d)| d)
    }
}

/// Serde for an `f64` that may be non-finite: finite values as JSON numbers, the others as the
/// strings `"NaN"`, `"inf"`, `"-inf"` (JSON has no such numbers).
pub(crate) mod any_f64 {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else if v.is_nan() {
            s.serialize_str("NaN")
        } else if *v > 0.0 {
            s.serialize_str("inf")
        } else {
            s.serialize_str("-inf")
        }
    }

    #[derive(Deserialize)]
    #[serde(untagged)]
    pub(crate) enum NumOrText {
        Num(f64),
        Text(String),
    }

    pub(crate) fn from(v: NumOrText) -> Result<f64, String> {
        match v {
            NumOrText::Num(x) => Ok(x),
            NumOrText::Text(t) => match t.as_str() {
                "NaN" => Ok(f64::NAN),
                "inf" => Ok(f64::INFINITY),
                "-inf" => Ok(f64::NEG_INFINITY),
                _ => Err(format!("{t:?} is not a number")),
            },
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        from(NumOrText::deserialize(d)?).map_err(serde::de::Error::custom)
    }
}

/// [`any_f64`] for a vector.
pub(crate) mod any_f64_vec {
    use serde::ser::SerializeSeq;
    use serde::{Deserialize, Deserializer, Serializer};

    use super::any_f64::{self, NumOrText};

    struct One(f64);
    impl serde::Serialize for One {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            any_f64::serialize(&self.0, s)
        }
    }

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(v.len()))?;
        for x in v {
            seq.serialize_element(&One(*x))?;
        }
        seq.end()
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        Vec::<NumOrText>::deserialize(d)?
            .into_iter()
            .map(|v| any_f64::from(v).map_err(serde::de::Error::custom))
            .collect()
    }
}
