//! The HTML page: summary table, then per channel the figures of Zhang & Basseville (2014)
//! and Zhang (2021), alarm and diagnosis tables, and errors.

use std::fmt::Write as _;
use std::io::{self, Write};

use glrmon_wire::{Alarm, Diagnosis, IsolationResult};

use crate::channel::{ChannelState, MAX_ALARMS, MAX_COMPONENTS, MAX_DIAGNOSES, MAX_ERRORS};
use crate::clock::{Zone, date, format_time};
use crate::decimate::ColumnId;
use crate::escape::escape;
use crate::labels::{ChannelLabels, MagnitudeUnit};
use crate::svg::{Axis, Category, Figure, ONSET, PALETTE, RED, Swatch, TimeAxis, fmt_num};
use crate::{Provenance, Report};

/// Lines drawn per figure of vector components (ε_k, θ̂); the rest are named in the caption.
const MAX_LINES: usize = 10;
/// Alarms that get an isolation figure; the others are in the alarm table.
const MAX_ISOLATION_FIGURES: usize = 8;
/// Faults per isolation figure: the isolated ones first, then the largest statistics.
const MAX_ISOLATION_ROWS: usize = 24;
/// Faults with their own colour and legend entry on a Lasso path figure.
const MAX_PATH_LEGEND: usize = 12;
/// Alarms and onsets labelled with their k on the l_k figure; with more, only markers.
const MAX_LABELS: usize = 6;
/// Items listed per cell of the summary table.
const MAX_SUMMARY_ITEMS: usize = 8;
/// Figures of ε_k or θ̂ per channel, one per unit; the components of further units are
/// named in a note.
const MAX_UNIT_FIGURES: usize = 6;

pub(crate) const CSS: &str = "body{font-family:Helvetica,Arial,sans-serif;margin:0 auto;max-width:1080px;padding:16px 20px;color:#222;line-height:1.35}\
h1{font-size:24px;margin-bottom:4px}h2{font-size:20px;border-bottom:2px solid #ddd;padding-bottom:4px;margin-top:36px}h3{font-size:16px;margin-top:24px}\
table{border-collapse:collapse;margin:8px 0 16px;font-size:13px}th,td{border:1px solid #ccc;padding:3px 7px;text-align:left;vertical-align:top}\
th{background:#f2f2f2}td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}\
figure{margin:14px 0 22px}figcaption{font-size:13px;color:#555;margin-top:2px}svg.fig{max-width:100%;height:auto;display:block}\
.isolated{color:#b11;font-weight:bold}.note{color:#666;font-size:13px}code{background:#f4f4f4;padding:0 3px}\
nav a{margin-right:12px}details{margin:6px 0 12px}summary{cursor:pointer}\
.provenance{color:#444;font-size:13px;margin-top:0}";

pub(crate) fn write_page<W: Write>(report: &Report, mut out: W) -> io::Result<()> {
    let title = escape(&report.options.title);
    write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title><style>{CSS}</style></head><body>\n<h1>{title}</h1>\n"
    )?;
    if let Some(p) = &report.options.provenance {
        out.write_all(provenance_line(p).as_bytes())?;
    }
    let mut meta = format!(
        "{} records over {} channel{}. Letters of Zhang &amp; Basseville (2014): ε<sub>k</sub> innovation, l<sub>k</sub> GLR statistic, h threshold, r̂ onset, θ̂ magnitude; λ the Lasso penalty of Zhang (2021).",
        report.records,
        report.channels.len(),
        if report.channels.len() == 1 { "" } else { "s" }
    );
    if report.dropped_records > 0 {
        let _ = write!(
            meta,
            " {} records of channels beyond the first {} were not reported.",
            report.dropped_records,
            crate::MAX_CHANNELS
        );
    }
    if report.unknown_records > 0 {
        let _ = write!(
            meta,
            " {} records of an unknown type were skipped.",
            report.unknown_records
        );
    }
    writeln!(out, "<p class=\"note\">{meta}</p>")?;

    if report.channels.is_empty() {
        out.write_all(b"<p>No records.</p>\n</body></html>\n")?;
        return Ok(());
    }

    let channels = report.ordered_channels();
    out.write_all(b"<nav>")?;
    for (i, (name, _)) in channels.iter().enumerate() {
        write!(out, "<a href=\"#ch-{i}\">{}</a>", escape(name))?;
    }
    out.write_all(b"</nav>\n")?;
    out.write_all(summary_table(&channels).as_bytes())?;

    let mut fig_id = 0;
    for (i, (name, ch)) in channels.into_iter().enumerate() {
        let section = channel_section(
            i,
            name,
            ch,
            report.options.width_points,
            report.options.zone,
            &mut fig_id,
        );
        out.write_all(section.as_bytes())?;
    }
    out.write_all(b"</body></html>\n")?;
    out.flush()
}

/// `glrmon 0.1.0 (git …), configuration …, data …, made … (UTC)`: what made the report,
/// from what and when.
fn provenance_line(p: &Provenance) -> String {
    let data = if p.data.is_empty() {
        "–".to_owned()
    } else {
        p.data
            .iter()
            .map(|d| format!("<code>{}</code>", escape(d)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!(
        "<p class=\"provenance\">Made by glrmon {} from configuration <code>{}</code> and data {data}, at {} (UTC).</p>\n",
        escape(&p.version),
        escape(&p.config),
        p.made.strftime("%Y-%m-%dT%H:%M:%SZ")
    )
}

fn summary_table(channels: &[(&String, &ChannelState)]) -> String {
    let mut s = String::from(
        "<h2>Summary</h2>\n<table class=\"summary\"><tr><th>Channel</th><th>Samples</th><th>k range</th><th>Alarms</th><th>Episodes ended</th><th>Onsets r̂</th><th>Isolated faults</th><th>Diagnoses</th><th>Model consistency</th><th>Errors by code</th></tr>\n",
    );
    for (i, (name, ch)) in channels.iter().enumerate() {
        let k_range = ch
            .k_range
            .map_or("–".to_owned(), |(lo, hi)| format!("{lo} … {hi}"));
        let onsets = listing(
            ch.alarms.iter().map(|a| a.onset.to_string()),
            ch.alarms_total,
            ", ",
        );
        // Each alarm's final isolation: its update's when one came.
        let isolated = listing(
            ch.alarms.iter().map(|a| {
                let view = IsolationView::last(ch, a);
                let at = if view.k == a.k {
                    format!("k={}", a.k)
                } else {
                    format!("k={} (alarm k={})", view.k, a.k)
                };
                format!("{at}: {}", isolated_cell(view.isolation))
            }),
            ch.alarms_total,
            "<br>",
        );
        let diagnoses = listing(
            ch.diagnoses.iter().map(|d| {
                let est: Vec<String> = d
                    .support
                    .iter()
                    .map(|f| {
                        let v = d.estimate.get(f).map_or("?".to_owned(), |v| fmt_num(*v));
                        format!("{}={v}", escape(f))
                    })
                    .collect();
                format!(
                    "k={} [{}…{}]: {}",
                    d.k,
                    d.from,
                    d.to,
                    if est.is_empty() {
                        "empty support".to_owned()
                    } else {
                        est.join(", ")
                    }
                )
            }),
            ch.diagnoses_total,
            "<br>",
        );
        let consistency = if ch.consistency_total == 0 {
            "fits".to_owned()
        } else {
            listing(
                ch.consistency.iter().map(|c| {
                    format!(
                        "k={}: {} (mean εᵀΣ⁻¹ε {} vs [{}, {}])",
                        c.k,
                        escape(&c.state),
                        fmt_num(c.nis_mean),
                        fmt_num(c.band[0]),
                        fmt_num(c.band[1])
                    )
                }),
                ch.consistency_total,
                "<br>",
            )
        };
        let errors = if ch.error_counts.is_empty() {
            "0".to_owned()
        } else {
            ch.error_counts
                .iter()
                .map(|(code, n)| format!("{code}: {n}"))
                .collect::<Vec<_>>()
                .join("<br>")
        };
        let _ = writeln!(
            s,
            "<tr><td><a href=\"#ch-{i}\"><code>{}</code></a></td><td class=\"num\">{}</td><td class=\"num\">{k_range}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{onsets}</td><td>{isolated}</td><td>{diagnoses}</td><td>{consistency}</td><td>{errors}</td></tr>",
            escape(name),
            ch.stats,
            ch.alarms_total,
            ch.alarm_ends,
        );
    }
    s.push_str("</table>\n");
    s
}

/// Up to [`MAX_SUMMARY_ITEMS`] items, then how many more there are of `total`.
fn listing(items: impl Iterator<Item = String>, total: u64, sep: &str) -> String {
    let shown: Vec<String> = items.take(MAX_SUMMARY_ITEMS).collect();
    if shown.is_empty() {
        return "–".to_owned();
    }
    let more = total.saturating_sub(shown.len() as u64);
    let mut s = shown.join(sep);
    if more > 0 {
        let _ = write!(s, "{sep}… {more} more");
    }
    s
}

fn isolated_names(isolation: &[IsolationResult]) -> Vec<String> {
    isolation
        .iter()
        .filter(|i| i.isolated)
        .map(|i| escape(&i.fault))
        .collect()
}

/// `none`, or the isolated faults' names highlighted.
fn isolated_cell(isolation: &[IsolationResult]) -> String {
    let names = isolated_names(isolation);
    if names.is_empty() {
        "none".to_owned()
    } else {
        format!("<span class=\"isolated\">{}</span>", names.join(", "))
    }
}

/// The isolation tests of an alarm (at its crossing) or of its update.
struct IsolationView<'a> {
    /// Where the tests ran.
    k: u64,
    alarm_k: u64,
    glr: f64,
    threshold: f64,
    onset: u64,
    isolation: &'a [IsolationResult],
}

impl<'a> IsolationView<'a> {
    /// The alarm's last isolation: its update's when one came, else its own.
    fn last(ch: &'a ChannelState, a: &'a Alarm) -> Self {
        match ch.update_of(a) {
            Some(u) => IsolationView {
                k: u.k,
                alarm_k: u.alarm_k,
                glr: u.glr,
                threshold: u.threshold,
                onset: u.onset,
                isolation: &u.isolation,
            },
            None => IsolationView {
                k: a.k,
                alarm_k: a.k,
                glr: a.glr,
                threshold: a.threshold,
                onset: a.onset,
                isolation: &a.isolation,
            },
        }
    }
}

fn figure(fig: &Figure, id: &mut usize, caption: &str) -> String {
    *id += 1;
    format!(
        "<figure>{}<figcaption>{caption}</figcaption></figure>\n",
        fig.render(*id)
    )
}

fn channel_section(
    index: usize,
    name: &str,
    ch: &ChannelState,
    width_points: usize,
    zone: Zone,
    fig_id: &mut usize,
) -> String {
    let mut s = format!(
        "<section id=\"ch-{index}\">\n<h2>Channel <code>{}</code></h2>\n",
        escape(name)
    );
    let t_axis = TimeAxis {
        pairs: time_pairs(ch),
        zone,
    };
    let t_pairs = &t_axis.pairs;
    let mut facts = format!("{} stat records", ch.stats);
    if let Some((lo, hi)) = ch.k_range {
        let _ = write!(facts, ", k = {lo} … {hi}");
    }
    if let (Some(first), Some(last)) = (t_pairs.first(), t_pairs.last()) {
        let _ = write!(
            facts,
            ", t = {} … {} (grey second row under the k axis{})",
            format_time(first.1, zone),
            format_time(last.1, zone),
            date(first.1, zone).map_or_else(String::new, |d| format!(", times of day on {d}"))
        );
    }
    let _ = write!(
        facts,
        ". Series are decimated to at most {width_points} points each, keeping each bucket's minimum and maximum, so spikes stay visible."
    );
    let _ = writeln!(s, "<p class=\"note\">{facts}</p>");

    if ch.stats > 0 {
        s.push_str(&innovation_figures(ch, &t_axis, fig_id));
        s.push_str(&glr_figure(ch, &t_axis, fig_id));
        s.push_str(&residual_bound_figures(ch, &t_axis, fig_id));
        s.push_str(&onset_figure(ch, &t_axis, fig_id));
        s.push_str(&magnitude_figures(ch, &t_axis, fig_id));
    } else {
        s.push_str(
            "<p class=\"note\">No stat records for this channel: no time-series figures.</p>\n",
        );
    }
    if ch.alarmed() {
        s.push_str(&alarm_section(ch, zone, fig_id));
    }
    if ch.diagnoses_total > 0 {
        s.push_str(&diagnosis_section(ch, fig_id));
    }
    if !ch.error_counts.is_empty() {
        s.push_str(&error_section(ch));
    }
    s.push_str("</section>\n");
    s
}

/// `(k, t)` pairs of the decimated time column, for the second row of x labels.
fn time_pairs(ch: &ChannelState) -> Vec<(f64, f64)> {
    let mut pairs: Vec<(f64, f64)> = ch
        .grid
        .segments(ch.time)
        .into_iter()
        .flatten()
        .map(|(k, t)| (k as f64, t))
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    pairs.dedup_by(|a, b| a.0 == b.0);
    pairs
}

fn segments_f64(ch: &ChannelState, col: ColumnId) -> Vec<Vec<(f64, f64)>> {
    ch.grid
        .segments(col)
        .into_iter()
        .map(|seg| seg.into_iter().map(|(k, v)| (k as f64, v)).collect())
        .collect()
}

fn k_axis(ch: &ChannelState) -> Axis {
    let (lo, hi) = ch.k_range.unwrap_or((0, 1));
    Axis::linear(lo as f64, hi as f64, "sample index k").integer()
}

/// Value range over several columns, if any has values.
fn columns_range(ch: &ChannelState, cols: &[ColumnId]) -> Option<(f64, f64)> {
    cols.iter()
        .filter_map(|c| ch.grid.range(*c))
        .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
}

/// The `MAX_LINES` components with the largest peak |value|, in index order.
fn pick_components(ch: &ChannelState, cols: &[ColumnId]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..cols.len()).collect();
    if idx.len() > MAX_LINES {
        idx.sort_by(|a, b| {
            let pa = cols.get(*a).map_or(0.0, |c| ch.grid.peak_abs(*c));
            let pb = cols.get(*b).map_or(0.0, |c| ch.grid.peak_abs(*c));
            pb.total_cmp(&pa)
        });
        idx.truncate(MAX_LINES);
        idx.sort_unstable();
    }
    idx
}

/// Alarm episodes (shaded), alarm lines and markers on a figure over k.
fn decorate_alarms(fig: &mut Figure, ch: &ChannelState) {
    if ch.episodes.is_empty() && ch.alarms.is_empty() {
        return;
    }
    let last_k = ch.k_range.map_or(0, |r| r.1) as f64;
    for ep in &ch.episodes {
        let end = ep.end.map_or(last_k, |e| e as f64);
        fig.vband(ep.start as f64, end, RED, 0.10, "alarm-episode");
    }
    for a in &ch.alarms {
        fig.vline(a.k as f64, RED, 1.2, None, "alarm-marker");
        fig.top_marker(a.k as f64, RED, "alarm-marker");
    }
    if !ch.alarms.is_empty() {
        fig.legend("alarm", RED, Swatch::Triangle);
    }
    if !ch.episodes.is_empty() {
        fig.legend("alarm episode (alarm → alarm_end)", RED, Swatch::Band);
    }
}

/// Components of a per-sample vector (ε_k or θ̂) drawn on one figure: those of one
/// unit, with the unit's axis label and the factor that turns the stored values into
/// that unit.
struct UnitGroup {
    /// The unit as the axis shows it (`cm`, `model units`), empty when not known.
    unit: String,
    /// Whether `unit` is a unit symbol, written in brackets (`θ̂ [cm]`), rather than
    /// words, written in parentheses (`θ̂ (model units)`).
    symbol: bool,
    /// Component indices, in order.
    members: Vec<usize>,
}

impl UnitGroup {
    /// `what [unit]`, `what (words)` or `what`.
    fn label(&self, what: &str) -> String {
        match (self.unit.as_str(), self.symbol) {
            ("", _) => what.to_owned(),
            (unit, true) => format!("{what} [{unit}]"),
            (words, false) => format!("{what} ({words})"),
        }
    }
}

/// Components `0..n` grouped by their unit (`unit_of`: the unit and whether it is a
/// symbol), groups in order of their first member.
fn group_by_unit(n: usize, unit_of: impl Fn(usize) -> (String, bool)) -> Vec<UnitGroup> {
    let mut groups: Vec<UnitGroup> = Vec::new();
    for i in 0..n {
        let (unit, symbol) = unit_of(i);
        match groups.iter_mut().find(|g| g.unit == unit) {
            Some(g) => g.members.push(i),
            None => groups.push(UnitGroup {
                unit,
                symbol,
                members: vec![i],
            }),
        }
    }
    groups
}

/// The groups beyond [`MAX_UNIT_FIGURES`], as a note naming their components.
fn extra_groups_note(groups: &[UnitGroup], name: impl Fn(usize) -> String) -> String {
    let rest: Vec<String> = groups
        .iter()
        .skip(MAX_UNIT_FIGURES)
        .map(|g| {
            let names: Vec<String> = g.members.iter().map(|i| escape(&name(*i))).collect();
            format!("{} ({})", names.join(", "), escape(&g.unit))
        })
        .collect();
    if rest.is_empty() {
        String::new()
    } else {
        format!(
            "<p class=\"note\">Not drawn (more than {MAX_UNIT_FIGURES} units): {}.</p>\n",
            rest.join("; ")
        )
    }
}

/// The output's name: the labels', else `y{i}` as a configuration without
/// `[channels.columns]` names it.
fn output_name(labels: Option<&ChannelLabels>, i: usize) -> String {
    labels
        .and_then(|l| l.output(i))
        .map_or_else(|| format!("y{i}"), |o| o.name.clone())
}

/// Values of `col` times `factor`, as drawn segments.
fn scaled_segments(ch: &ChannelState, col: ColumnId, factor: f64) -> Vec<Vec<(f64, f64)>> {
    ch.grid
        .segments(col)
        .into_iter()
        .map(|seg| {
            seg.into_iter()
                .map(|(k, v)| (k as f64, v * factor))
                .collect()
        })
        .collect()
}

/// ε_k: one figure per output unit when the channel is labelled, in raw units (the
/// stored model-unit values times each output's scale), else one figure in model units.
/// An output whose unit is not given has a figure of its own: two unknown units are
/// not assumed to be one.
fn innovation_figures(ch: &ChannelState, t_axis: &TimeAxis, fig_id: &mut usize) -> String {
    let labels = ch.labels.as_ref();
    let n = ch.innovation.len();
    let groups = match labels {
        Some(l) => group_by_unit(n, |i| match l.output(i).and_then(|o| o.unit.clone()) {
            Some(unit) => (unit, true),
            None => (format!("raw units of {}", output_name(labels, i)), false),
        }),
        None => vec![UnitGroup {
            unit: "model units".to_owned(),
            symbol: false,
            members: (0..n).collect(),
        }],
    };
    let scale = |i: usize| labels.and_then(|l| l.output(i)).map_or(1.0, |o| o.scale);
    let mut s = String::new();
    let several = groups.len() > 1;
    for group in groups.iter().take(MAX_UNIT_FIGURES) {
        let cols: Vec<(usize, ColumnId)> = group
            .members
            .iter()
            .filter_map(|i| ch.innovation.get(*i).map(|c| (*i, *c)))
            .collect();
        let (lo, hi) = cols
            .iter()
            .filter_map(|(i, c)| {
                ch.grid
                    .range(*c)
                    .map(|(a, b)| (a * scale(*i), b * scale(*i)))
            })
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
            .unwrap_or((-1.0, 1.0));
        let axis = group.label("ε_k");
        let title = format!("Kalman innovation {axis}");
        let title = if several {
            let names: Vec<String> = group
                .members
                .iter()
                .map(|i| output_name(labels, *i))
                .collect();
            format!("{title}: {}", names.join(", "))
        } else {
            title
        };
        let mut fig = Figure::new(
            &title,
            k_axis(ch),
            Axis::linear_padded(lo, hi, 0.05, &axis),
            200.0,
        );
        fig.set_class("innovation");
        fig.set_secondary_x(t_axis);
        decorate_alarms(&mut fig, ch);
        fig.hline(0.0, "#999", None, "zero");
        let own: Vec<ColumnId> = cols.iter().map(|(_, c)| *c).collect();
        let picked = pick_components(ch, &own);
        for (n, p) in picked.iter().enumerate() {
            let Some((i, col)) = cols.get(*p) else {
                continue;
            };
            let color = PALETTE.get(n % PALETTE.len()).copied().unwrap_or("#000");
            fig.polyline(scaled_segments(ch, *col, scale(*i)), color, 1.0, None);
            fig.legend(&output_name(labels, *i), color, Swatch::Line);
        }
        let mut caption = "Innovation of the Kalman filter of the fault-free model, one line per output (Zhang &amp; Basseville 2014, Fig. 3 top)".to_owned();
        caption.push_str(match labels {
            None => ", in the model's units: with <code>[channels.scaling]</code>, (raw − offset)/scale.",
            Some(l) if l.scaled => ", in the outputs' raw units: the model works in (raw − offset)/scale (<code>[channels.scaling]</code>), and each output's innovation is drawn times its scale.",
            Some(_) => ", in the outputs' raw units (the model's, without <code>[channels.scaling]</code>).",
        });
        caption.push_str(&omitted_note(picked.len(), cols.len(), "outputs"));
        if ch.innovation.is_empty() {
            caption.push_str(" No innovation values were recorded.");
        }
        s.push_str(&figure(&fig, fig_id, &caption));
    }
    s.push_str(&extra_groups_note(&groups, |i| output_name(labels, i)));
    s
}

fn omitted_note(shown: usize, total: usize, what: &str) -> String {
    if shown < total {
        format!(
            " Showing {shown} of {total} {what}: those with the largest |value|{}.",
            if total > MAX_COMPONENTS {
                format!(" among the first {MAX_COMPONENTS}")
            } else {
                String::new()
            }
        )
    } else {
        String::new()
    }
}

fn glr_figure(ch: &ChannelState, t_axis: &TimeAxis, fig_id: &mut usize) -> String {
    let glr_range = ch.grid.range(ch.glr);
    let thr_range = ch.grid.range(ch.threshold);
    let alarm_threshold = ch.alarms.first().map(|a| a.threshold);
    let mut hi = 0.0f64;
    let mut lo = 0.0f64;
    for (a, b) in [glr_range, thr_range].into_iter().flatten() {
        lo = lo.min(a);
        hi = hi.max(b);
    }
    for a in &ch.alarms {
        hi = hi.max(a.glr).max(a.threshold);
    }
    let mut fig = Figure::new(
        "GLR statistic l_k",
        k_axis(ch),
        Axis::linear(lo, if hi > lo { hi * 1.05 } else { 1.0 }, "l_k"),
        260.0,
    );
    fig.set_class("glr");
    fig.set_secondary_x(t_axis);
    decorate_alarms(&mut fig, ch);
    let mut onsets: Vec<u64> = ch.alarms.iter().map(|a| a.onset).collect();
    onsets.sort_unstable();
    onsets.dedup();
    for r in &onsets {
        fig.vline(*r as f64, ONSET, 1.4, Some("3 3"), "onset-marker");
        fig.top_marker(*r as f64, ONSET, "onset-marker");
    }
    // Labels above the plot avoid every marker and each other: alarm labels prefer the
    // right of their marker, onset labels the left (an onset precedes its alarm).
    let mut placed: Vec<(f64, f64)> = (ch.alarms.iter().map(|a| a.k))
        .chain(onsets.iter().copied())
        .map(|k| fig.marker_extent(k as f64))
        .collect();
    if ch.alarms.len() <= MAX_LABELS {
        for a in &ch.alarms {
            fig.top_label(
                a.k as f64,
                &format!("alarm k={}", a.k),
                RED,
                true,
                &mut placed,
            );
        }
    }
    if onsets.len() <= MAX_LABELS {
        for r in &onsets {
            fig.top_label(*r as f64, &format!("r̂={r}"), ONSET, false, &mut placed);
        }
    }
    fig.polyline(segments_f64(ch, ch.glr), PALETTE[0], 1.2, None);
    fig.legend_math("l_k", PALETTE[0], Swatch::Line);
    let mut threshold_text = String::new();
    match (thr_range, alarm_threshold) {
        (Some((a, b)), _) if a == b => {
            fig.hline(a, RED, Some("7 4"), "threshold");
            threshold_text = fmt_num(a);
        }
        (Some(_), _) => {
            fig.raw("<g class=\"threshold\">");
            fig.polyline(segments_f64(ch, ch.threshold), RED, 1.6, Some("7 4"));
            fig.raw("</g>");
            threshold_text = "varying".to_owned();
        }
        (None, Some(h)) => {
            fig.hline(h, RED, Some("7 4"), "threshold");
            threshold_text = fmt_num(h);
        }
        (None, None) => {}
    }
    if !threshold_text.is_empty() {
        fig.legend(
            &format!("threshold h = {threshold_text}"),
            RED,
            Swatch::Dashed,
        );
    }
    if !onsets.is_empty() {
        fig.legend("onset r̂ at alarm", ONSET, Swatch::Dashed);
    }
    for a in &ch.alarms {
        fig.dots([(a.k as f64, a.glr)], RED, 3.5);
    }
    let mut caption = "GLR statistic l<sub>k</sub> over the window of candidate onsets (Zhang &amp; Basseville 2014, eq. (35), Fig. 3 bottom); an alarm is raised when l<sub>k</sub> &gt; h. Gaps: no admissible onset yet.".to_owned();
    if glr_range.is_none() {
        caption.push_str(" No l<sub>k</sub> values (no onset was ever admissible).");
    }
    figure(&fig, fig_id, &caption)
}

/// Each residual the detector kind pairs with a threshold (the kernel method's r_FD
/// with σ_FD, r_FI,i with σ_FI,i), drawn as Li, Boem, Pin & Parisini draw them in
/// their Figs 2-6: the residual and its time-varying threshold.
fn residual_bound_figures(ch: &ChannelState, t_axis: &TimeAxis, fig_id: &mut usize) -> String {
    let Some(labels) = &ch.labels else {
        return String::new();
    };
    let mut s = String::new();
    for bound in &labels.residual_bounds {
        let (Some(&r), Some(&th)) = (
            ch.residual.get(bound.residual),
            ch.residual.get(bound.threshold),
        ) else {
            continue;
        };
        let (lo, hi) = columns_range(ch, &[r, th]).unwrap_or((0.0, 1.0));
        let lo = lo.min(0.0);
        let mut fig = Figure::new(
            &format!("The {} and its threshold", bound.name),
            k_axis(ch),
            Axis::linear(lo, if hi > lo { hi * 1.05 } else { lo + 1.0 }, "residual"),
            220.0,
        );
        fig.set_class("residual-bound");
        fig.set_secondary_x(t_axis);
        decorate_alarms(&mut fig, ch);
        fig.polyline(segments_f64(ch, r), PALETTE[0], 1.2, None);
        fig.legend(&bound.name, PALETTE[0], Swatch::Line);
        fig.raw("<g class=\"threshold\">");
        fig.polyline(segments_f64(ch, th), RED, 1.6, Some("7 4"));
        fig.raw("</g>");
        fig.legend(
            "threshold (worst case of the bounded noise)",
            RED,
            Swatch::Dashed,
        );
        let caption = format!(
            "The {} against its threshold, the largest value noise within the configured \
             bounds could give it (Li, Boem, Pin &amp; Parisini, (32), (37)): above it, a fault \
             (detection) or a candidate ruled out (isolation). Isolation residuals are 0 \
             outside an isolation episode.",
            escape(&bound.name)
        );
        s.push_str(&figure(&fig, fig_id, &caption));
    }
    s
}

fn onset_figure(ch: &ChannelState, t_axis: &TimeAxis, fig_id: &mut usize) -> String {
    let (lo, hi) = ch.grid.range(ch.onset).unwrap_or((0.0, 1.0));
    let (lo, hi) = ch.alarms.iter().fold((lo, hi), |(l, h), a| {
        (l.min(a.onset as f64), h.max(a.onset as f64))
    });
    let mut fig = Figure::new(
        "Onset estimate r̂",
        k_axis(ch),
        Axis::linear_padded(lo, hi, 0.04, "r̂").integer(),
        200.0,
    );
    fig.set_class("onset");
    fig.set_secondary_x(t_axis);
    decorate_alarms(&mut fig, ch);
    if let Some((k0, k1)) = ch.k_range {
        fig.polyline(
            [[(k0 as f64, k0 as f64), (k1 as f64, k1 as f64)]],
            "#aaa",
            1.0,
            Some("2 3"),
        );
        fig.legend("r = k", "#aaa", Swatch::Dotted);
    }
    let points = segments_f64(ch, ch.onset).into_iter().flatten();
    fig.dots(points, PALETTE[3], 1.6);
    fig.legend("r̂ (maximising onset)", PALETTE[3], Swatch::Dot);
    for a in &ch.alarms {
        fig.diamond(a.k as f64, a.onset as f64, RED, 5.0);
    }
    if !ch.alarms.is_empty() {
        fig.legend("r̂ reported at alarm", RED, Swatch::Diamond);
    }
    figure(
        &fig,
        fig_id,
        "Onset r̂ maximising the GLR over the window at each k (Zhang &amp; Basseville 2014, eq. (36)); dots are each bucket's extremes.",
    )
}

/// θ̂ of an alarmed channel: one figure per unit of the faults' magnitudes, each with
/// the window's θ̂ at its r̂ (thin, faint) and, during episodes, the episode's θ̂ at its
/// own onset (thick). A channel without alarms gets a one-line note instead: its θ̂
/// fits noise.
fn magnitude_figures(ch: &ChannelState, t_axis: &TimeAxis, fig_id: &mut usize) -> String {
    if !ch.alarmed() {
        return if ch.magnitude.is_empty() {
            String::new()
        } else {
            "<p class=\"note\">No alarm on this channel: its magnitude estimates, which then fit noise, are not drawn.</p>\n".to_owned()
        };
    }
    let labels = ch.labels.as_ref();
    let names = ch.fault_names();
    let name = |i: usize| names.get(i).cloned().unwrap_or_else(|| format!("θ̂[{i}]"));
    let groups = match labels {
        Some(l) => group_by_unit(ch.magnitude.len(), |i| {
            let unit = l.fault_unit(i);
            let symbol = matches!(unit, MagnitudeUnit::Signal { unit: Some(_), .. });
            (unit.label(), symbol)
        }),
        None => vec![UnitGroup {
            unit: String::new(),
            symbol: false,
            members: (0..ch.magnitude.len()).collect(),
        }],
    };
    let mut s = String::new();
    let several = groups.len() > 1;
    for group in groups.iter().take(MAX_UNIT_FIGURES) {
        s.push_str(&magnitude_figure(ch, group, several, &name, t_axis, fig_id));
    }
    s.push_str(&extra_groups_note(&groups, name));
    s
}

fn magnitude_figure(
    ch: &ChannelState,
    group: &UnitGroup,
    several: bool,
    name: &dyn Fn(usize) -> String,
    t_axis: &TimeAxis,
    fig_id: &mut usize,
) -> String {
    let window: Vec<(usize, ColumnId)> = group
        .members
        .iter()
        .filter_map(|i| ch.magnitude.get(*i).map(|c| (*i, *c)))
        .collect();
    let episode_col = |i: usize| ch.episode_magnitude.get(i).copied();
    let all: Vec<ColumnId> = window
        .iter()
        .flat_map(|(i, c)| std::iter::once(*c).chain(episode_col(*i)))
        .collect();
    let (lo, hi) = columns_range(ch, &all).unwrap_or((-1.0, 1.0));
    let axis = group.label("θ̂");
    let title = format!("Magnitude estimate {axis}");
    let title = if several {
        let names: Vec<String> = window.iter().map(|(i, _)| name(*i)).collect();
        format!("{title}: {}", names.join(", "))
    } else {
        title
    };
    let mut fig = Figure::new(
        &title,
        k_axis(ch),
        Axis::linear_padded(lo.min(0.0), hi.max(0.0), 0.05, &axis),
        220.0,
    );
    fig.set_class("magnitude");
    fig.set_secondary_x(t_axis);
    decorate_alarms(&mut fig, ch);
    fig.hline(0.0, "#999", None, "zero");
    let own: Vec<ColumnId> = window.iter().map(|(_, c)| *c).collect();
    let picked = pick_components(ch, &own);
    let mut episodes = false;
    for (n, p) in picked.iter().enumerate() {
        let Some((i, col)) = window.get(*p) else {
            continue;
        };
        let color = PALETTE.get(n % PALETTE.len()).copied().unwrap_or("#000");
        fig.raw("<g class=\"window-magnitude\" opacity=\"0.45\">");
        fig.polyline(segments_f64(ch, *col), color, 1.0, None);
        fig.raw("</g>");
        if let Some(ep) = episode_col(*i).filter(|c| ch.grid.range(*c).is_some()) {
            episodes = true;
            fig.raw("<g class=\"episode-magnitude\">");
            fig.polyline(segments_f64(ch, ep), color, 2.4, None);
            fig.raw("</g>");
        }
        fig.legend(&name(*i), color, Swatch::Line);
    }
    if episodes {
        fig.legend("thick: the episode's θ̂ at its onset", "#444", Swatch::Line);
        fig.legend("faint: the window's θ̂ at r̂", "#bbb", Swatch::Line);
    }
    let mut caption = "Magnitude θ̂ of each fault of the dictionary (Zhang &amp; Basseville 2014, eq. (34)): thin and faint, at the onset r̂ that maximises l<sub>k</sub> in the window".to_owned();
    if episodes {
        caption.push_str("; thick, during each alarm episode, the episode's θ̂ at its own onset over every sample since (the <code>stat</code> records' <code>episode</code>). Once a persisting fault's onset has left the window, the window's θ̂ fits its settled response with the transient of a fault starting inside the window and shrinks while the fault does not: the thick line is the fault's magnitude.");
    } else {
        caption.push_str(" (the records carry no episode estimate: a glrmon before it, or a detector that follows no onset).");
    }
    caption.push_str(match (group.unit.as_str(), several) {
        ("", _) => " Units: those of each fault's column.",
        (_, true) => " Faults whose magnitudes are in other units are on the other θ̂ figures.",
        (_, false) => "",
    });
    caption.push_str(&omitted_note(picked.len(), window.len(), "faults"));
    if ch.magnitude.is_empty() {
        caption.push_str(" No θ̂ values were recorded.");
    }
    figure(&fig, fig_id, &caption)
}

fn alarm_section(ch: &ChannelState, zone: Zone, fig_id: &mut usize) -> String {
    let mut s = format!(
        "<h3>Alarms</h3>\n<p class=\"note\">{} alarm{}, {} episode{} ended.{}</p>\n",
        ch.alarms_total,
        if ch.alarms_total == 1 { "" } else { "s" },
        ch.alarm_ends,
        if ch.alarm_ends == 1 { "" } else { "s" },
        if ch.alarms_total > MAX_ALARMS as u64 {
            format!(" Only the first {MAX_ALARMS} are shown.")
        } else {
            String::new()
        }
    );
    if ch.alarms.is_empty() {
        return s;
    }
    s.push_str("<p class=\"note\">An alarm is raised at the crossing (k: the first sample with l<sub>k</sub> &gt; h); its isolation tests are run again at its update, <code>isolation_delay</code> samples later, if the episode is still on then.</p>\n");
    s.push_str("<table><tr><th>k</th><th>t</th><th>l<sub>k</sub></th><th>h</th><th>r̂</th><th>episode end k</th><th>θ̂</th><th>isolated at k</th><th>update k</th><th>r̂ at update</th><th>isolated at update</th></tr>\n");
    for a in &ch.alarms {
        let episode = ch.episodes.iter().find(|e| e.start == a.k);
        let end = episode
            .and_then(|e| e.end)
            .map_or("open".to_owned(), |e| e.to_string());
        let theta = largest_magnitudes(a, ch.labels.as_ref());
        let (update_k, update_onset, update_isolated) = match (ch.update_of(a), a.update_k) {
            (Some(u), _) => (
                u.k.to_string(),
                u.onset.to_string(),
                isolated_cell(&u.isolation),
            ),
            (None, None) => ("–".to_owned(), "–".to_owned(), "–".to_owned()),
            (None, Some(due)) => {
                let why = match episode.and_then(|e| e.end) {
                    Some(end) if end <= due => "none: the episode ended first",
                    _ => "not seen",
                };
                (due.to_string(), "–".to_owned(), why.to_owned())
            }
        };
        let _ = writeln!(
            s,
            "<tr><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{end}</td><td>{}</td><td>{}</td><td class=\"num\">{update_k}</td><td class=\"num\">{update_onset}</td><td>{update_isolated}</td></tr>",
            a.k,
            a.t.map_or("–".to_owned(), |t| format_time(t, zone)),
            fmt_num(a.glr),
            fmt_num(a.threshold),
            a.onset,
            theta,
            isolated_cell(&a.isolation),
        );
    }
    s.push_str("</table>\n");
    for a in ch.alarms.iter().take(MAX_ISOLATION_FIGURES) {
        let view = IsolationView::last(ch, a);
        if !view.isolation.is_empty() {
            s.push_str(&isolation_figure(&view, fig_id));
        }
    }
    if ch.alarms.len() > MAX_ISOLATION_FIGURES {
        let _ = writeln!(
            s,
            "<p class=\"note\">Isolation figures are drawn for the first {MAX_ISOLATION_FIGURES} alarms; the table lists the rest.</p>"
        );
    }
    s
}

/// `name=θ̂` (with its unit when the labels name one: `LI201_bias=1.32 cm`) for the
/// [`MAX_LINES`] faults with the largest |θ̂| (dictionary order), and how many are left
/// out.
fn largest_magnitudes(a: &Alarm, labels: Option<&ChannelLabels>) -> String {
    let mut pairs: Vec<(usize, &String, f64)> = a
        .faults
        .iter()
        .zip(&a.magnitude)
        .enumerate()
        .map(|(i, (f, v))| (i, f, *v))
        .collect();
    let total = pairs.len();
    if total > MAX_LINES {
        pairs.sort_by(|x, y| y.2.abs().total_cmp(&x.2.abs()));
        pairs.truncate(MAX_LINES);
        pairs.sort_by_key(|p| p.0);
    }
    let mut s = pairs
        .iter()
        .map(|(i, f, v)| {
            let unit = labels
                .filter(|l| l.faults.get(*i).is_some_and(|l| &l.name == *f))
                .and_then(|l| l.fault_unit(*i).suffix())
                .map_or_else(String::new, |u| format!(" {}", escape(&u)));
            format!("{}={}{unit}", escape(f), fmt_num(*v))
        })
        .collect::<Vec<_>>()
        .join(", ");
    if total > pairs.len() {
        let _ = write!(s, " (the {} largest |θ̂| of {total} faults)", pairs.len());
    }
    s
}

fn isolation_figure(a: &IsolationView<'_>, fig_id: &mut usize) -> String {
    let stat_max = |i: &glrmon_wire::IsolationResult| i.minmax.max(i.sensitivity);
    let mut rows: Vec<usize> = (0..a.isolation.len()).collect();
    let total = rows.len();
    if total > MAX_ISOLATION_ROWS {
        rows.sort_by(|x, y| {
            let (Some(p), Some(q)) = (a.isolation.get(*x), a.isolation.get(*y)) else {
                return std::cmp::Ordering::Equal;
            };
            q.isolated
                .cmp(&p.isolated)
                .then(stat_max(q).total_cmp(&stat_max(p)))
        });
        rows.truncate(MAX_ISOLATION_ROWS);
        rows.sort_unstable();
    }
    let shown: Vec<&glrmon_wire::IsolationResult> =
        rows.iter().filter_map(|i| a.isolation.get(*i)).collect();
    let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
    let max = shown
        .iter()
        .map(|i| {
            finite(i.minmax)
                .max(finite(i.sensitivity))
                .max(finite(i.threshold))
        })
        .fold(0.0f64, f64::max);
    let min_thr = shown
        .iter()
        .map(|i| i.threshold)
        .filter(|t| t.is_finite() && *t > 0.0)
        .fold(f64::INFINITY, f64::min);
    let log = min_thr.is_finite() && max / min_thr > 50.0;
    let x = if log {
        let lo = 10f64.powf((min_thr / 20.0).log10().floor());
        let hi = 10f64.powf((max * 1.2).log10().ceil());
        Axis::log(lo, hi, "test statistic (log scale)")
    } else {
        Axis::linear(
            0.0,
            if max > 0.0 { max * 1.12 } else { 1.0 },
            "test statistic",
        )
    };
    let base = if log { x.lo() } else { 0.0 };
    let categories: Vec<Category> = shown
        .iter()
        .map(|i| Category {
            label: truncate(&i.fault, 28),
            emphasis: i.isolated,
        })
        .collect();
    let title = if a.k == a.alarm_k {
        format!(
            "Isolation at alarm k = {} (l_k = {} > h = {}, r̂ = {})",
            a.k,
            fmt_num(a.glr),
            fmt_num(a.threshold),
            a.onset
        )
    } else {
        format!(
            "Isolation at k = {}, update of alarm k = {} (l_k = {}, h = {}, r̂ = {})",
            a.k,
            a.alarm_k,
            fmt_num(a.glr),
            fmt_num(a.threshold),
            a.onset
        )
    };
    let mut fig = Figure::categorical(&title, x, categories, 30.0);
    fig.set_class("isolation");
    let (c_min, c_sens) = (PALETTE[0], PALETTE[1]);
    let x0 = fig.xp(base);
    for (r, iso) in shown.iter().enumerate() {
        let (top, row_h) = fig.row(r);
        if iso.isolated {
            fig.raw(&format!(
                r#"<rect class="isolated-row" x="0" y="{top:.1}" width="{:.1}" height="{row_h:.1}" fill="{RED}" fill-opacity="0.12"/>"#,
                fig.width()
            ));
        }
        let bar_h = row_h * 0.32;
        for (j, (v, color)) in [(iso.minmax, c_min), (iso.sensitivity, c_sens)]
            .into_iter()
            .enumerate()
        {
            let y = top + row_h * 0.16 + j as f64 * bar_h;
            let px = fig.xp(finite(v).max(base));
            fig.raw(&format!(
                r#"<rect x="{x0:.1}" y="{y:.1}" width="{:.1}" height="{bar_h:.1}" fill="{color}"/>"#,
                (px - x0).max(0.0)
            ));
            let (tx, anchor, fill) = if px > fig.width() - 60.0 {
                (px - 4.0, "end", "#fff")
            } else {
                (px + 4.0, "start", "#333")
            };
            fig.raw_front(&format!(
                r#"<text x="{tx:.1}" y="{:.1}" font-size="10" text-anchor="{anchor}" fill="{fill}">{}</text>"#,
                y + bar_h - 1.5,
                fmt_num(v)
            ));
        }
        let tx = fig.xp(iso.threshold);
        fig.raw(&format!(
            r#"<line class="threshold" x1="{tx:.1}" x2="{tx:.1}" y1="{top:.1}" y2="{:.1}" stroke="{RED}" stroke-width="1.6" stroke-dasharray="5 3"/>"#,
            top + row_h
        ));
    }
    fig.legend("minmax", c_min, Swatch::Bar);
    fig.legend("sensitivity", c_sens, Swatch::Bar);
    fig.legend("threshold", RED, Swatch::Dashed);
    fig.legend("isolated fault (bold name)", RED, Swatch::Band);
    let mut caption = "Minmax test (Zhang &amp; Basseville 2014, eq. (41)) and sensitivity test (Basseville 1996, §3.2.2) per fault against its threshold; highlighted faults are declared present. An alarm's figure shows its last isolation: at its update when one came, else at its crossing.".to_owned();
    if total > shown.len() {
        let _ = write!(
            caption,
            " Showing {} of {total} faults: the isolated ones, then the largest statistics.",
            shown.len()
        );
    }
    figure(&fig, fig_id, &caption)
}

fn truncate(s: &str, max: usize) -> String {
    if s.chars().count() > max {
        let mut t: String = s.chars().take(max - 1).collect();
        t.push('…');
        t
    } else {
        s.to_owned()
    }
}

fn diagnosis_section(ch: &ChannelState, fig_id: &mut usize) -> String {
    let mut s = format!(
        "<h3>Sparse diagnoses</h3>\n<p class=\"note\">{} diagnos{}.{}</p>\n",
        ch.diagnoses_total,
        if ch.diagnoses_total == 1 { "is" } else { "es" },
        if ch.diagnoses_total > MAX_DIAGNOSES as u64 {
            format!(" Only the first {MAX_DIAGNOSES} are shown.")
        } else {
            String::new()
        }
    );
    for d in &ch.diagnoses {
        let estimates: Vec<String> = d
            .support
            .iter()
            .map(|f| {
                let v = d.estimate.get(f).map_or("?".to_owned(), |v| fmt_num(*v));
                format!("<code>{}</code> = {v}", escape(f))
            })
            .collect();
        let _ = writeln!(
            s,
            "<table><tr><th>k</th><th>span</th><th>residual</th><th>λ</th><th>plateau</th><th>support (least-squares refit)</th></tr><tr><td class=\"num\">{}</td><td class=\"num\">{} … {}</td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">[{}, {}]</td><td>{}</td></tr></table>",
            d.k,
            d.from,
            d.to,
            escape(&d.residual),
            fmt_num(d.lambda),
            fmt_num(d.plateau[0]),
            fmt_num(d.plateau[1]),
            if estimates.is_empty() {
                "empty".to_owned()
            } else {
                estimates.join(", ")
            }
        );
        match path_axis(d) {
            Some(x) => {
                s.push_str(&lasso_path_figure(d, x.clone(), fig_id));
                s.push_str(&support_size_figure(d, x, fig_id));
            }
            None => s.push_str(
                "<p class=\"note\">No regularisation path with positive λ was recorded.</p>\n",
            ),
        }
    }
    s
}

/// The log λ axis of a diagnosis: its path, the chosen λ and the plateau.
fn path_axis(d: &Diagnosis) -> Option<Axis> {
    let positive = |v: &f64| v.is_finite() && *v > 0.0;
    let (lo, hi) = d
        .path_lambda
        .iter()
        .filter(|v| positive(v))
        .fold(None, |acc: Option<(f64, f64)>, v| {
            Some(acc.map_or((*v, *v), |(l, h)| (l.min(*v), h.max(*v))))
        })?;
    let (lo, hi) = [d.lambda, d.plateau[0], d.plateau[1]]
        .iter()
        .filter(|v| positive(v))
        .fold((lo, hi), |(l, h), v| (l.min(*v), h.max(*v)));
    Some(Axis::log(lo / 1.15, hi * 1.15, "λ (log scale)"))
}

fn mark_lambda(fig: &mut Figure, d: &Diagnosis) {
    let (p0, p1) = (d.plateau[0], d.plateau[1]);
    if p0.is_finite() && p1.is_finite() && p1 > 0.0 {
        fig.vband(p0.max(f64::MIN_POSITIVE), p1, PALETTE[2], 0.15, "plateau");
        fig.legend("plateau (support unchanged)", PALETTE[2], Swatch::Band);
    }
    if d.lambda.is_finite() && d.lambda > 0.0 {
        fig.vline(d.lambda, "#000", 1.4, None, "chosen-lambda");
        fig.legend(
            &format!("chosen λ = {}", fmt_num(d.lambda)),
            "#000",
            Swatch::Line,
        );
    }
}

fn lasso_path_figure(d: &Diagnosis, x: Axis, fig_id: &mut usize) -> String {
    let n_faults = d.faults.len();
    let coef = |row: &Vec<f64>, j: usize| row.get(j).copied().filter(|v| v.is_finite());
    let (lo, hi) = d
        .path_coefficients
        .iter()
        .flat_map(|row| (0..n_faults).filter_map(move |j| coef(row, j)))
        .chain(d.estimate.values().copied().filter(|v| v.is_finite()))
        .fold((0.0f64, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    let mut fig = Figure::new(
        &format!(
            "Lasso path θ̂(λ), diagnosis at k = {} (span {} … {})",
            d.k, d.from, d.to
        ),
        x,
        Axis::linear_padded(lo, hi, 0.06, "θ̂_j(λ)"),
        260.0,
    );
    fig.set_class("lasso-path");
    mark_lambda(&mut fig, d);
    fig.hline(0.0, "#999", None, "zero");
    let path = |j: usize| -> Vec<(f64, f64)> {
        d.path_lambda
            .iter()
            .zip(&d.path_coefficients)
            .filter(|(l, _)| l.is_finite() && **l > 0.0)
            .filter_map(|(l, row)| coef(row, j).map(|v| (*l, v)))
            .collect()
    };
    let in_support = |name: &String| d.support.contains(name);
    let mut colored = Vec::new();
    let mut others = 0;
    for (j, name) in d.faults.iter().enumerate() {
        if in_support(name) && colored.len() < MAX_PATH_LEGEND {
            colored.push(j);
        } else {
            others += 1;
            fig.polyline([path(j)], "#c4c4c4", 0.9, None);
        }
    }
    if others > 0 {
        fig.legend(&format!("other faults ({others})"), "#c4c4c4", Swatch::Line);
    }
    for (n, j) in colored.iter().enumerate() {
        let color = PALETTE.get(n % PALETTE.len()).copied().unwrap_or("#000");
        let Some(name) = d.faults.get(*j) else {
            continue;
        };
        fig.polyline([path(*j)], color, 1.9, None);
        fig.legend(name, color, Swatch::Line);
        if let Some(v) = d.estimate.get(name)
            && d.lambda.is_finite()
            && d.lambda > 0.0
        {
            let (px, py) = (fig.xp(d.lambda), fig.yp(*v));
            fig.raw(&format!(
                    r##"<circle class="refit" cx="{px:.1}" cy="{py:.1}" r="4.5" fill="#fff" stroke="{color}" stroke-width="2"/>"##
                ));
        }
    }
    if !colored.is_empty() && !d.estimate.is_empty() {
        fig.legend(
            "least-squares refit on the support (at chosen λ)",
            "#555",
            Swatch::Ring,
        );
    }
    figure(
        &fig,
        fig_id,
        "Lasso estimate of each fault magnitude along the regularisation path (Zhang 2021, eq. (39)); coloured: the selected support, grey: the other faults. Circles: least-squares refit on the support (Zhang 2021, Fig. 3).",
    )
}

fn support_size_figure(d: &Diagnosis, x: Axis, fig_id: &mut usize) -> String {
    let points: Vec<(f64, f64)> = d
        .path_lambda
        .iter()
        .zip(&d.path_support_sizes)
        .filter(|(l, _)| l.is_finite() && **l > 0.0)
        .map(|(l, n)| (*l, *n as f64))
        .collect();
    let max = points.iter().map(|p| p.1).fold(1.0f64, f64::max);
    let mut fig = Figure::new(
        "Support size per λ",
        x,
        Axis::linear(0.0, max + 1.0, "non-zero θ̂_j").integer(),
        180.0,
    );
    fig.set_class("support-size");
    mark_lambda(&mut fig, d);
    fig.polyline([points.clone()], PALETTE[0], 1.0, None);
    let (p0, p1) = (d.plateau[0], d.plateau[1]);
    let mut in_plateau = false;
    for (l, n) in &points {
        if *l >= p0 && *l <= p1 {
            in_plateau = true;
            fig.diamond(*l, *n, RED, 4.0);
        } else {
            fig.dots([(*l, *n)], PALETTE[0], 2.5);
        }
    }
    fig.legend("support size", PALETTE[0], Swatch::Dot);
    if in_plateau {
        fig.legend("in the plateau", RED, Swatch::Diamond);
    }
    figure(
        &fig,
        fig_id,
        "Number of non-zero components of the Lasso estimate per λ; the support is chosen in the flat range (Zhang 2021, Fig. 2).",
    )
}

fn error_section(ch: &ChannelState) -> String {
    let total = ch.errors_total();
    let mut s = format!(
        "<h3>Errors</h3>\n<p class=\"note\">{total} error records.</p>\n<table><tr><th>code</th><th>count</th></tr>"
    );
    for (code, n) in &ch.error_counts {
        let _ = write!(
            s,
            "<tr><td><code>{code}</code></td><td class=\"num\">{n}</td></tr>"
        );
    }
    s.push_str("</table>\n");
    let _ = write!(
        s,
        "<details><summary>First {} error records{}</summary><table><tr><th>k</th><th>code</th><th>stage</th><th>message</th></tr>",
        ch.errors.len(),
        if total > MAX_ERRORS as u64 {
            format!(" of {total}")
        } else {
            String::new()
        }
    );
    for e in &ch.errors {
        let _ = write!(
            s,
            "<tr><td class=\"num\">{}</td><td><code>{}</code></td><td>{}</td><td>{}</td></tr>",
            e.k.map_or("–".to_owned(), |k| k.to_string()),
            e.code.as_str(),
            e.stage.as_str(),
            escape(&e.message)
        );
    }
    s.push_str("</table></details>\n");
    s
}
