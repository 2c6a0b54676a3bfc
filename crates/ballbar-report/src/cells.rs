//! Table cells and scales shared by the page's sections: the page and the sections it calls
//! (rotary tests, tolerances) take them from here, so that no section imports the page back.

/// `<td>` with the number at `decimals` and its full value in `data-v`.
pub(crate) fn td(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!(r#"<td class="num" data-v="{v}">{v:.decimals$}</td>"#)
    } else {
        "<td class=\"num\">—</td>".into()
    }
}

/// The largest |value| of some curves (0 for none): what a plot's µm/division must hold.
pub(crate) fn max_abs<'a>(curves: impl IntoIterator<Item = &'a Vec<f64>>) -> f64 {
    curves.into_iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()))
}
