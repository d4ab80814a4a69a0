//! Reports built from synthetic records: figures present, names escaped, numbers shown,
//! memory bounded.

use std::collections::BTreeMap;

use glrmon_wire::{
    Alarm, AlarmEnd, Diagnosis, ErrorCode, ErrorRecord, IsolationResult, IsolationUpdate, Record,
    Stage, Stat,
};

use super::*;
use crate::escape::escape;

const CHANNEL: &str = "pump<3>&co";
const THRESHOLD: f64 = 23.5;

fn stat(channel: &str, k: u64, glr: Option<f64>) -> Record {
    Record::from(Stat {
        channel: channel.into(),
        k,
        t: Some(k as f64 * 0.5),
        glr,
        onset: glr.map(|_| k.saturating_sub(20)),
        magnitude: if glr.is_some() {
            vec![0.1 * k as f64, -0.2]
        } else {
            Vec::new()
        },
        rank: 2,
        innovation: vec![(k as f64).sin(), (k as f64).cos()],
        residual: Vec::new(),
        threshold: Some(THRESHOLD),
        episode: None,
    })
}

/// l_k of a fault that starts at k = 200: None while the window fills (k < 50), noise
/// level before the fault, then a ramp that crosses the threshold at k = 215.
fn glr_at(k: u64) -> Option<f64> {
    match k {
        0..50 => None,
        50..200 => Some(2.0 + (k % 7) as f64),
        _ => Some(2.0 + 1.5 * (k - 199) as f64),
    }
}

fn alarm() -> Record {
    Record::from(Alarm {
        channel: CHANNEL.into(),
        k: 215,
        t: Some(107.5),
        glr: 26.0,
        threshold: THRESHOLD,
        onset: 201,
        magnitude: vec![4.1, 0.05],
        isolation: vec![
            IsolationResult {
                excluded: None,
                fault: "x0_jump".into(),
                minmax: 31.25,
                sensitivity: 35.0,
                threshold: 6.63,
                isolated: true,
                ambiguous_with: Vec::new(),
            },
            IsolationResult {
                excluded: None,
                fault: "<b>x1</b>".into(),
                minmax: 0.75,
                sensitivity: 4.5,
                threshold: 6.63,
                isolated: false,
                ambiguous_with: Vec::new(),
            },
        ],
        faults: vec!["x0_jump".into(), "<b>x1</b>".into()],
        update_k: Some(220),
    })
}

/// The isolation update of [`alarm`], 5 samples after it.
fn update() -> Record {
    Record::from(IsolationUpdate {
        channel: CHANNEL.into(),
        k: 220,
        t: Some(110.0),
        alarm_k: 215,
        glr: 33.5,
        threshold: THRESHOLD,
        onset: 200,
        magnitude: vec![4.0, 0.01],
        isolation: vec![
            IsolationResult {
                excluded: None,
                fault: "x0_jump".into(),
                minmax: 48.5,
                sensitivity: 50.0,
                threshold: 6.63,
                isolated: true,
                ambiguous_with: Vec::new(),
            },
            IsolationResult {
                excluded: None,
                fault: "<b>x1</b>".into(),
                minmax: 0.5,
                sensitivity: 3.25,
                threshold: 6.63,
                isolated: false,
                ambiguous_with: Vec::new(),
            },
        ],
        faults: vec!["x0_jump".into(), "<b>x1</b>".into()],
    })
}

fn alarm_end() -> Record {
    Record::from(AlarmEnd {
        channel: CHANNEL.into(),
        k: 320,
        t: Some(160.0),
        onset: 201,
        duration: 105,
        peak_glr: 180.0,
    })
}

fn diagnosis() -> Record {
    let faults: Vec<String> = ["f00", "f01", "f02", "f03"].map(String::from).to_vec();
    let path_lambda: Vec<f64> = (0..20).map(|i| 10f64.powf(1.0 - 0.2 * i as f64)).collect();
    let path_coefficients: Vec<Vec<f64>> = path_lambda
        .iter()
        .map(|l| {
            let shrink = |v: f64| (v - l).max(0.0);
            vec![shrink(2.0), 0.0, shrink(1.0), shrink(0.05)]
        })
        .collect();
    let path_support_sizes = path_coefficients
        .iter()
        .map(|row| row.iter().filter(|v| **v != 0.0).count())
        .collect();
    Record::from(Diagnosis {
        channel: CHANNEL.into(),
        k: 320,
        from: 201,
        to: 320,
        support: vec!["f00".into(), "f02".into()],
        estimate: BTreeMap::from([("f00".into(), 2.0), ("f02".into(), 1.0)]),
        lambda: 0.25,
        plateau: [0.06, 0.9],
        residual: Diagnosis::RESIDUAL_KALMAN.into(),
        path_support_sizes,
        faults,
        path_lambda,
        path_coefficients,
    })
}

fn error(channel: &str, k: Option<u64>, code: ErrorCode) -> Record {
    Record::from(ErrorRecord {
        channel: channel.into(),
        k,
        code,
        message: format!("channel \"{channel}\": <bad> sample"),
        stage: Stage::Processing,
    })
}

fn render(report: &Report) -> String {
    let mut out = Vec::new();
    report.write_html(&mut out).unwrap();
    String::from_utf8(out).unwrap()
}

/// The full scenario: 400 samples of one channel with an alarm, its end and a
/// diagnosis, two errors; and a channel with only errors, named like a script.
fn scenario() -> Report {
    let mut report = Report::new(ReportOptions {
        title: "Replay <test>".into(),
        ..ReportOptions::default()
    });
    for k in 0..400 {
        report.add(&stat(CHANNEL, k, glr_at(k)));
        match k {
            215 => report.add(&alarm()),
            220 => report.add(&update()),
            320 => {
                report.add(&alarm_end());
                report.add(&diagnosis());
            }
            _ => {}
        }
    }
    report.add(&error(CHANNEL, Some(399), ErrorCode::Gap));
    report.add(&error(CHANNEL, None, ErrorCode::InvalidJson));
    report.add(&error("<script>", Some(3), ErrorCode::WrongDimension));
    report
}

/// The `<svg …>` elements with `class` among their classes.
fn figures_of_class<'a>(html: &'a str, class: &str) -> Vec<&'a str> {
    html.split("<svg ")
        .skip(1)
        .filter(|s| {
            s.split_once("class=\"")
                .and_then(|(_, rest)| rest.split_once('"'))
                .is_some_and(|(classes, _)| classes.split(' ').any(|c| c == class))
        })
        .collect()
}

#[test]
fn report_has_one_svg_per_expected_figure() {
    let html = render(&scenario());
    // ε_k, l_k, r̂, θ̂, one isolation figure, Lasso path and support size.
    assert_eq!(html.matches("<svg").count(), 7);
    assert_eq!(html.matches("</svg>").count(), 7);
    for class in [
        "innovation",
        "glr",
        "onset",
        "magnitude",
        "isolation",
        "lasso-path",
        "support-size",
    ] {
        assert_eq!(figures_of_class(&html, class).len(), 1, "{class}");
    }
    // Clip-path ids are document-global: they must be unique.
    for id in 1..=7 {
        assert_eq!(html.matches(&format!("id=\"clip{id}\"")).count(), 1);
    }
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(
        !html.contains("<script"),
        "no JavaScript, and names are escaped"
    );
    let without_namespace = html.replace("xmlns=\"http://www.w3.org/2000/svg\"", "");
    assert!(!without_namespace.contains("http"), "no network resources");
}

#[test]
fn glr_figure_has_threshold_alarm_episode_and_onset() {
    let html = render(&scenario());
    let glr = figures_of_class(&html, "glr");
    let glr = glr.first().expect("an l_k figure");
    assert!(glr.contains("class=\"threshold\""), "threshold line");
    assert!(glr.contains("stroke-dasharray"), "dashed threshold");
    assert!(
        glr.contains("threshold h = 23.5"),
        "threshold in the legend"
    );
    assert!(glr.contains("class=\"alarm-marker\""), "alarm marker");
    assert!(glr.contains("alarm k=215"), "alarm label");
    assert!(glr.contains("class=\"alarm-episode\""), "shaded episode");
    assert!(glr.contains("class=\"onset-marker\""), "onset marker");
    assert!(glr.contains("r̂=201"), "onset label");
    // glr is None for k < 50: the line starts later, so there is exactly one polyline
    // for l_k (the threshold is a <line>).
    assert_eq!(glr.matches("<polyline").count(), 1);
    // Time is shown under the k axis (t = k / 2).
    assert!(glr.contains(">100 s<"), "t labels: {glr}");
}

#[test]
fn summary_shows_the_numbers() {
    let html = render(&scenario());
    let summary = html
        .split("<table class=\"summary\">")
        .nth(1)
        .and_then(|s| s.split("</table>").next())
        .expect("summary table");
    let row = summary
        .split("<tr>")
        .find(|r| r.contains("pump&lt;3&gt;&amp;co"))
        .expect("row of the channel");
    for want in [
        ">400<",                                                 // samples
        ">0 … 399<",                                             // k range
        ">1<",                                                   // alarms, episodes ended
        ">201<",                                                 // onset r̂
        "k=220 (alarm k=215): <span class=\"isolated\">x0_jump", // final isolation
        "f00=2",                                                 // diagnosis support and estimate
        "f02=1",
        "gap: 1",
        "invalid_json: 1",
    ] {
        assert!(row.contains(want), "{want} missing in {row}");
    }
    assert!(!row.contains("x1"), "x1 is not isolated: {row}");
    let script_row = summary
        .split("<tr>")
        .find(|r| r.contains("&lt;script&gt;"))
        .expect("row of the error-only channel");
    assert!(script_row.contains("wrong_dimension: 1"));
}

/// The alarm table gives both isolations of an alarm: at its crossing and at its
/// update; an alarm whose episode ended before its update says so.
#[test]
fn alarm_table_shows_the_crossing_and_the_update() {
    let html = render(&scenario());
    let table = html
        .split("<h3>Alarms</h3>")
        .nth(1)
        .and_then(|s| s.split("</table>").next())
        .expect("alarm table");
    assert!(table.contains("<th>update k</th>"), "{table}");
    let row = table.split("<tr>").nth(2).expect("the alarm's row");
    for want in [
        ">215<", // the crossing
        ">201<", // r̂ at the crossing
        ">320<", // the episode's end
        ">220<", // the update
        ">200<", // r̂ at the update
    ] {
        assert!(row.contains(want), "{want} missing in {row}");
    }
    // θ̂ names it once, each isolation column once.
    assert_eq!(
        row.matches("<span class=\"isolated\">x0_jump</span>")
            .count(),
        2,
        "{row}"
    );

    let mut report = Report::new(ReportOptions::default());
    let Record::Alarm(short) = alarm() else {
        unreachable!()
    };
    let short = Alarm {
        update_k: Some(400),
        ..short
    };
    report.add(&Record::from(short));
    report.add(&alarm_end());
    let html = render(&report);
    assert!(html.contains("none: the episode ended first"), "{html}");
}

#[test]
fn names_are_escaped() {
    let html = render(&scenario());
    assert!(html.contains("<title>Replay &lt;test&gt;</title>"));
    assert!(html.contains("pump&lt;3&gt;&amp;co"));
    assert!(!html.contains("pump<3>"));
    assert!(html.contains("&lt;script&gt;"));
    assert!(!html.contains("<script>"));
    assert!(
        html.contains("&lt;b&gt;x1&lt;/b&gt;"),
        "fault names escaped"
    );
    assert!(!html.contains("<b>x1"));
    assert!(
        html.contains("&lt;bad&gt; sample"),
        "error messages escaped"
    );
    assert_eq!(escape("a<b>&\"'"), "a&lt;b&gt;&amp;&quot;&#39;");
}

#[test]
fn error_only_channel_and_empty_report() {
    let mut report = Report::new(ReportOptions::default());
    let html = render(&report);
    assert!(html.contains("No records."));
    assert_eq!(html.matches("<svg").count(), 0);

    report.add(&error("<script>", None, ErrorCode::NonFinite));
    let html = render(&report);
    assert_eq!(html.matches("<svg").count(), 0);
    assert!(html.contains("No stat records for this channel"));
    assert!(html.contains("non_finite"));
}

#[test]
fn isolation_figure_highlights_isolated_faults() {
    let html = render(&scenario());
    let iso = figures_of_class(&html, "isolation");
    let iso = iso.first().expect("an isolation figure");
    assert_eq!(iso.matches("class=\"isolated-row\"").count(), 1);
    assert!(iso.contains(r#"font-weight="bold">x0_jump<"#));
    // The alarm's last isolation: its update's, 5 samples after the crossing.
    assert!(iso.contains("update of alarm k = 215"), "{iso}");
    assert!(
        iso.contains(">48.5<") && iso.contains(">3.25<"),
        "bar values"
    );
    assert!(!iso.contains(">31.25<"), "not the crossing's tests");
    assert_eq!(
        iso.matches("class=\"threshold\"").count(),
        2,
        "one per fault"
    );
}

#[test]
fn lasso_figures_mark_lambda_and_plateau() {
    let html = render(&scenario());
    for class in ["lasso-path", "support-size"] {
        let fig = figures_of_class(&html, class);
        let fig = fig.first().expect("figure");
        assert!(fig.contains("class=\"chosen-lambda\""), "{class}");
        assert!(fig.contains("class=\"plateau\""), "{class}");
        assert!(fig.contains("chosen λ = 0.25"), "{class}");
    }
    let path = figures_of_class(&html, "lasso-path");
    let path = path.first().expect("figure");
    assert!(
        path.contains(">f00<") && path.contains(">f02<"),
        "support in the legend"
    );
    assert!(path.contains("other faults (2)"));
    assert_eq!(path.matches("class=\"refit\"").count(), 2);
}

#[test]
fn decimation_keeps_the_point_budget_and_the_spike() {
    let width_points = 2000;
    let mut report = Report::new(ReportOptions {
        width_points,
        ..ReportOptions::default()
    });
    let spike_k = 654_321;
    for k in 0..1_000_000u64 {
        let glr = if k == spike_k {
            1e4
        } else {
            1.0 + (k % 13) as f64 * 0.1
        };
        report.add(&Record::from(Stat {
            channel: "c".into(),
            k,
            t: None,
            glr: Some(glr),
            onset: Some(k / 2),
            magnitude: vec![0.0; 3],
            rank: 3,
            innovation: vec![0.0; 2],
            residual: Vec::new(),
            threshold: Some(20.0),
            episode: None,
        }));
    }
    let ch = report.channels.get("c").expect("channel");
    assert_eq!(ch.stats, 1_000_000);
    assert!(ch.grid.cells_used() <= width_points / 2);
    let glr: Vec<(u64, f64)> = ch.grid.segments(ch.glr).concat();
    assert!(glr.len() <= width_points, "{} points", glr.len());
    assert!(glr.len() >= width_points / 2, "{} points", glr.len());
    assert!(glr.contains(&(spike_k, 1e4)), "the spike survives");
    let max = glr.iter().map(|p| p.1).fold(f64::MIN, f64::max);
    assert_eq!(max, 1e4);

    let html = render(&report);
    let fig = figures_of_class(&html, "glr");
    let fig = fig.first().expect("l_k figure");
    let points = fig
        .split("<polyline")
        .nth(1)
        .and_then(|s| s.split("points=\"").nth(1))
        .and_then(|s| s.split('"').next())
        .expect("l_k polyline");
    assert!(points.split(' ').count() <= width_points);
    // 1e4 is the top of the axis (× 1.05): the spike reaches near the top.
    let min_y = points
        .split(' ')
        .filter_map(|p| p.split(',').nth(1)?.parse::<f64>().ok())
        .fold(f64::MAX, f64::min);
    assert!(min_y < 20.0, "spike drawn near the top, y = {min_y}");
}

#[test]
fn caps_bound_rare_records_and_channels() {
    let mut report = Report::new(ReportOptions::default());
    for i in 0..1000u64 {
        report.add(&error(
            &format!("ch{}", i % 100),
            Some(i),
            ErrorCode::UnknownChannel,
        ));
    }
    assert_eq!(report.channels.len(), MAX_CHANNELS);
    assert!(report.dropped_records > 0);
    let mut report = Report::new(ReportOptions::default());
    for i in 0..500 {
        report.add(&error("c", Some(i), ErrorCode::Gap));
        report.add(&alarm());
    }
    let ch = report.channels.values().next().expect("channel");
    assert_eq!(ch.errors.len(), channel::MAX_ERRORS);
    assert_eq!(ch.error_counts.get("gap"), Some(&500));
    let ch = report.channels.get(CHANNEL).expect("channel");
    assert_eq!(ch.alarms.len(), channel::MAX_ALARMS);
    assert_eq!(ch.alarms_total, 500);
    let html = render(&report);
    assert!(html.contains("… 492 more"));
}

#[test]
fn odd_records_do_not_panic() {
    let mut report = Report::new(ReportOptions {
        title: String::new(),
        width_points: 0,
        zone: crate::clock::Zone::Utc,
        provenance: None,
    });
    // An alarm_end without its alarm, out-of-order and extreme k, a diagnosis without a
    // path, rows of the wrong length, non-finite values.
    report.add(&alarm_end());
    report.add(&stat("c", u64::MAX, Some(f64::INFINITY)));
    report.add(&stat("c", 5, Some(1.0)));
    report.add(&stat("c", 0, None));
    let Record::Diagnosis(mut d) = diagnosis() else {
        unreachable!()
    };
    d.path_coefficients.truncate(3);
    d.path_coefficients.push(vec![f64::NAN]);
    d.path_support_sizes.clear();
    d.plateau = [-1.0, f64::NAN];
    report.add(&Record::from(d.clone()));
    d.path_lambda = vec![0.0, -1.0];
    d.lambda = 0.0;
    report.add(&Record::from(d));
    let Record::Alarm(mut a) = alarm() else {
        unreachable!()
    };
    a.isolation[0].minmax = f64::NAN;
    a.isolation[1].threshold = 0.0;
    a.faults.clear();
    report.add(&Record::from(a));
    let html = render(&report);
    assert!(html.ends_with("</body></html>\n"));
    assert!(html.contains("No regularisation path with positive λ"));
}

/// A live recording's wall-clock `t` labels the k axis with times of day and the facts
/// line with ISO-8601 times, not with "1.796e9 s".
#[test]
fn wall_clock_times_are_shown_as_times_of_day() {
    let t0 = 1_796_191_746.0;
    let mut report = Report::new(ReportOptions::default());
    for k in 0..400 {
        let Record::Stat(mut s) = stat(CHANNEL, k, glr_at(k)) else {
            unreachable!()
        };
        s.t = Some(t0 + k as f64 * 0.5);
        report.add(&Record::from(s));
    }
    let mut out = Vec::new();
    report.write_html(&mut out).unwrap();
    let html = String::from_utf8(out).unwrap();
    assert!(
        html.contains("t = 2026-12-02T06:09:06.000Z … 2026-12-02T06:12:25.500Z"),
        "facts line"
    );
    assert!(html.contains("times of day on 2026-12-02 UTC"));
    assert!(
        html.contains(">06:10:"),
        "a tick labelled with a time of day"
    );
    assert!(!html.contains("e9 s<"), "no epoch seconds on an axis");
}

/// Channels with alarms come first (then by name), and only they get θ̂ figures; the
/// episode's θ̂ of `stat` records is drawn over the window's, thick.
#[test]
fn alarmed_channels_first_and_theta_only_after_an_alarm() {
    let mut report = scenario();
    for k in 0..100 {
        report.add(&stat("aaa quiet", k, glr_at(k)));
    }
    let html = render(&report);
    let order: Vec<usize> = [CHANNEL, "&lt;script&gt;", "aaa quiet"]
        .iter()
        .map(|name| {
            let name = if *name == CHANNEL {
                escape(CHANNEL)
            } else {
                (*name).to_owned()
            };
            html.find(&format!("<h2>Channel <code>{name}</code></h2>"))
                .unwrap_or_else(|| panic!("{name}"))
        })
        .collect();
    assert!(order[0] < order[1] && order[0] < order[2], "{order:?}");
    assert!(order[1] < order[2], "then by name: '<' sorts before 'a'");
    let quiet = html
        .split("<h2>Channel <code>aaa quiet</code></h2>")
        .nth(1)
        .unwrap();
    let quiet = quiet.split("</section>").next().unwrap();
    assert!(figures_of_class(quiet, "magnitude").is_empty());
    assert!(!quiet.contains("θ̂["), "{quiet}");
    assert!(quiet.contains("No alarm on this channel"));
    assert!(figures_of_class(&html, "magnitude")[0].contains(">x0_jump<"));

    let mut report = scenario();
    for k in 215..320 {
        let Record::Stat(mut s) = stat(CHANNEL, k, glr_at(k)) else {
            unreachable!()
        };
        s.episode = Some(glrmon_wire::EpisodeEstimate {
            onset: 200,
            magnitude: vec![4.0, 0.0],
        });
        report.add(&Record::from(s));
    }
    let html = render(&report);
    let magnitude = figures_of_class(&html, "magnitude");
    assert!(magnitude[0].contains("class=\"episode-magnitude\""));
    assert!(magnitude[0].contains("thick: the episode"));
}

#[test]
fn residuals_paired_with_thresholds_are_drawn_with_them() {
    // The kernel kind's layout [r_FD, σ_FD, r_FI,1, σ_FI,1]: one figure per pair, the
    // residual and its dashed threshold; none for a channel without the labels.
    let mut report = Report::new(ReportOptions::default());
    report.label_channel(
        "plane",
        ChannelLabels {
            residual_bounds: vec![
                ResidualBound {
                    name: "detection r_FD".into(),
                    residual: 0,
                    threshold: 1,
                },
                ResidualBound {
                    name: "isolation r_FI of phi<1>".into(),
                    residual: 2,
                    threshold: 3,
                },
            ],
            ..ChannelLabels::default()
        },
    );
    for k in 0..300_u64 {
        let r = if k < 200 {
            0.01
        } else {
            0.02 * (k - 199) as f64
        };
        let Record::Stat(mut s) = stat("plane", k, Some(r / 0.74)) else {
            unreachable!()
        };
        s.residual = vec![r, 0.74, 0.0, 0.5];
        report.add(&Record::Stat(s));
        report.add(&stat("other", k, Some(1.0)));
    }
    let html = render(&report);
    let figures = figures_of_class(&html, "residual-bound");
    assert_eq!(figures.len(), 2);
    assert!(figures[0].contains("The detection r_FD and its threshold"));
    assert!(figures[1].contains("phi&lt;1&gt;"), "names are escaped");
    for f in &figures {
        assert!(f.contains("class=\"threshold\""));
        assert!(f.contains("stroke-dasharray"));
    }
}
