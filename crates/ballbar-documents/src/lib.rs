//! The documents `ballbar` writes for other programs, defined once as serde types: the command
//! line writes them, the report and the archive's replay read them back, and a plant's quality
//! system can read them with this crate (`shared/spec/cli.md` is the contract).
//!
//! - [`diagnosis::Diagnosis`]: `ballbar-diagnosis/1`, `ballbar diagnose --json` (and the
//!   diagnosis an archive keeps);
//! - [`fit::Fit`]: `ballbar-fit/1`, `ballbar fit --json`;
//! - [`vendor::VendorEntry`]: the entries of `vendor_comparison` in both;
//! - [`assumed::Assumed`]: the entries of `assumed` in both.
//!
//! Numbers: JSON has no NaN; a number that is not finite is written `null` and read back as
//! NaN, and a number an older document lacks reads as NaN (not known), never as 0.

pub mod advice;
pub mod assumed;
pub mod diagnosis;
pub mod fit;
mod num;
pub mod vendor;

pub use assumed::Assumed;
pub use vendor::VendorEntry;

#[cfg(test)]
mod tests {
    use crate::diagnosis::{Diagnosis, Why};

    /// What an archive written by an older version may hold reads as "not known": a number
    /// left out or `null` as NaN (never 0), a list left out as empty, `effects` left out as
    /// `None` (not an empty list), a sector of one number as not finite, a test this version
    /// does not know as not recorded.
    #[test]
    fn an_older_or_partial_document_reads_as_not_known_never_as_zero() {
        let d: Diagnosis = serde_json::from_str(
            r#"{"gap": {"noise_floor_um": null, "where": [{"plane": "XY", "sector_deg": [10.0]}]},
                "declined": [{"kind": "vibration", "why": {"test": "a_new_test", "x": 1}},
                             {"kind": "reversal_spike", "why": {"test": "held_out"}}]}"#,
        )
        .unwrap();
        assert!(d.gap.noise_floor_um.is_nan() && d.gap.base_rms_um.is_nan());
        assert_eq!(d.effects, None);
        assert!(d.aliased.is_empty() && d.gap.locking.is_none());
        let w = &d.gap.where_[0];
        assert!(w.sector_deg[0] == 10.0 && w.sector_deg[1].is_nan() && w.share.is_nan());
        assert_eq!(d.declined[0].why, Why::NotRecorded);
        assert!(
            matches!(d.declined[1].why, Why::HeldOut { held_out_t, .. } if held_out_t.is_nan())
        );
        assert_eq!(d.held_out.folds, None);
    }

    /// A number that is not finite is written `null` (JSON has no NaN) and read back as NaN.
    #[test]
    fn a_number_that_is_not_finite_is_written_null_and_read_back_as_nan() {
        let mut d: Diagnosis = serde_json::from_str("{}").unwrap();
        d.held_out.rms_before_um = f64::NAN;
        d.held_out.shrink = 0.5;
        let v = serde_json::to_value(&d).unwrap();
        assert_eq!(v["held_out"]["rms_before_um"], serde_json::Value::Null);
        let back: Diagnosis = serde_json::from_value(v).unwrap();
        assert!(back.held_out.rms_before_um.is_nan() && back.held_out.shrink == 0.5);
    }

    /// A vendor entry written before `ours_as_vendor` and `why` reads them as not given, and
    /// an entry without a `why` writes none.
    #[test]
    fn a_vendor_entry_without_ours_as_vendor_or_why_reads_them_as_not_given() {
        let e: crate::VendorEntry = serde_json::from_str(
            r#"{"plane": "XY", "feature": "AF_SQUARENESS", "unit": "µm/m", "vendor": -10.3,
                "ours": -3.1, "ours_u": 1.3, "vendor_valid": true, "note": "n"}"#,
        )
        .unwrap();
        assert_eq!((e.ours_as_vendor, e.why.as_deref()), (None, None));
        let v = serde_json::to_value(&e).unwrap();
        assert!(v.get("why").is_none() && v["ours_as_vendor"].is_null(), "{v}");
        let mut e = e;
        e.why = Some("the placement".into());
        e.ours_as_vendor = Some(-10.27);
        let back: crate::VendorEntry =
            serde_json::from_value(serde_json::to_value(&e).unwrap()).unwrap();
        assert_eq!(back, e);
    }

    fn where_(
        plane: &str,
        dir: &str,
        sector: [f64; 2],
        share: f64,
        rev: &[&str],
    ) -> crate::diagnosis::Where {
        serde_json::from_value(serde_json::json!({
            "plane": plane, "direction": dir, "sector_deg": sector, "share": share,
            "reversals": rev
        }))
        .unwrap()
    }

    /// The same arc and reversals in several planes and directions is one pattern, one line:
    /// every plane × direction named compactly, one share each with their sum; different arcs
    /// or reversals, or a plane and direction already in the group, start another.
    #[test]
    fn where_groups_one_pattern_over_several_runs() {
        use crate::diagnosis::grouped_where;
        let whole = [0.0, 360.0];
        let mut w: Vec<_> = ["XY", "YZ", "ZX"]
            .iter()
            .flat_map(|p| ["CW", "CCW"].map(|d| where_(p, d, whole, 1.0 / 6.0, &[])))
            .collect();
        w.push(where_("XY", "CW", [175.0, 185.0], 0.05, &["X"]));
        w.push(where_("XY", "CCW", [175.0, 185.0], 0.02, &["X"]));
        w.push(where_("YZ", "CW", [175.0, 185.0], 0.01, &["Y"]));
        let g = grouped_where(&w);
        assert_eq!(g.len(), 3);
        assert_eq!(g[0].runs_text(), "XY, YZ, ZX; CW and CCW");
        assert_eq!(g[0].share_text(), "16.7 % each, 100.0 % together");
        assert_eq!(g[0].sector_text(), "the whole circle");
        assert_eq!(g[1].runs_text(), "XY; CW and CCW");
        assert_eq!(g[1].share_text(), "5.0 %, 2.0 %");
        assert_eq!(g[1].sector_text(), "175° to 185°");
        assert_eq!(g[2].runs_text(), "YZ CW");
        assert_eq!(g[2].share_text(), "1.0 %");
    }
}
