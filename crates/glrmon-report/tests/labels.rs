//! A two-channel replay through the real monitors, reported with the channels' labels and
//! a provenance line: the page speaks of the plant's signals in their units, puts the
//! alarmed channel first and says nothing of θ̂ on the quiet one.

use glrmon_report::{ChannelLabels, Provenance, Report, ReportOptions};
use glrmon_wire::Sample;

/// Two channels with named columns and units: `tanks` (level LI201 in cm, outflow FI301
/// in m³/h, feed FIC101 in m³/h; scaled) gets a level-sensor bias, `boiler` (TI101 in
/// °C) none. By name `boiler` comes first; by alarms, `tanks`.
const PLANT: &str = r#"
[[channels]]
name = "tanks"
[channels.model]
F = [[0.9, 0.0], [0.0, 0.5]]
G = [[0.1], [1.0]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = 0.01
R = 0.01
[channels.scaling]
y_offset = [120.0, 4.0]
y_scale = [0.5, 0.1]
[channels.columns]
u = ["FIC101"]
y = ["LI201", "FI301"]
u_units = ["m³/h"]
y_units = ["cm", "m³/h"]
[channels.simulation]
inputs = ["normal(0, 1)"]
[[channels.faults]]
kind = "all_sensors"
[[channels.faults]]
kind = "all_actuators"
[channels.glr]
window = 40

[[channels]]
name = "boiler"
[channels.model]
F = [[0.8]]
H = [[1.0]]
Q = 0.01
R = 0.01
[channels.columns]
y = ["TI101"]
y_units = ["°C"]
[[channels.faults]]
kind = "all_sensors"
"#;

/// `n` raw samples of `channel`, with a bias of `bias` (raw units) on fault `fault`
/// from sample 300 when given.
fn samples(channel: &glrmon_spec::Channel, n: usize, fault: Option<(&str, f64)>) -> Vec<Sample> {
    let sim = glrmon_sim::from_channel(channel, 3).unwrap();
    let mut sim = match fault {
        Some((name, bias)) => {
            let magnitude = glrmon_sim::fault_magnitudes(channel, &[name.into()], &[bias]).unwrap();
            glrmon_sim::inject(
                sim,
                channel,
                glrmon_sim::Injection {
                    magnitude,
                    onset: 300,
                },
            )
            .unwrap()
        }
        None => sim,
    };
    (0..n)
        .map(|_| {
            let x = sim.next_sample();
            Sample {
                k: Some(x.k),
                t: None,
                u: x.u,
                y: x.y,
                p: x.p,
            }
        })
        .collect()
}

/// The page of the two channels' replay, each labelled from the configuration.
fn page() -> String {
    page_of(PLANT)
}

/// The page of the two channels' replay under configuration `text`.
fn page_of(text: &str) -> String {
    let config = glrmon_spec::parse(text).unwrap();
    let mut report = Report::new(ReportOptions {
        title: "replay".into(),
        provenance: Some(Provenance {
            version: "0.1.0 (git 1a2b3c4)".into(),
            config: "plant.toml".into(),
            data: vec!["tanks.csv".into(), "boiler.csv".into()],
            made: jiff::Timestamp::from_second(1_796_317_331).unwrap(),
        }),
        ..ReportOptions::default()
    });
    for (channel, fault) in [
        (&config.channels[0], Some(("LI201_bias", 1.32))),
        (&config.channels[1], None),
    ] {
        report.label_channel(&channel.name, ChannelLabels::from_channel(channel, text));
        let mut monitor = glrmon_monitor::Monitor::from_channel(channel).unwrap();
        let mut records = Vec::new();
        for s in samples(channel, 1300, fault) {
            monitor.on_sample(&s, &mut records);
            for r in records.drain(..) {
                report.add(&r);
            }
        }
    }
    let mut out = Vec::new();
    report.write_html(&mut out).unwrap();
    String::from_utf8(out).unwrap()
}

/// The `<section>` of channel `name`.
fn section<'a>(html: &'a str, name: &str) -> &'a str {
    let head = format!("<h2>Channel <code>{name}</code></h2>");
    let start = html
        .find(&head)
        .unwrap_or_else(|| panic!("no section {name}"));
    let from = html[..start].rfind("<section").unwrap();
    let end = html[start..].find("</section>").unwrap() + start;
    &html[from..end]
}

/// The `<svg>` elements of class `class` in `html`.
fn figures<'a>(html: &'a str, class: &str) -> Vec<&'a str> {
    html.split("<svg ")
        .skip(1)
        .filter(|s| {
            s.split_once("class=\"")
                .and_then(|(_, rest)| rest.split_once('"'))
                .is_some_and(|(classes, _)| classes.split(' ').any(|c| c == class))
        })
        .map(|s| s.split("</svg>").next().unwrap_or(s))
        .collect()
}

#[test]
fn the_page_names_signals_in_their_units_alarmed_channel_first() {
    let html = page();

    // Provenance under the title: version, configuration, data files, time in UTC.
    assert!(
        html.contains(
            "<p class=\"provenance\">Made by glrmon 0.1.0 (git 1a2b3c4) from configuration \
             <code>plant.toml</code> and data <code>tanks.csv</code>, <code>boiler.csv</code>, \
             at 2026-12-03T17:02:11Z (UTC).</p>"
        ),
        "{}",
        &html[..html.len().min(1500)]
    );

    // The alarmed channel first everywhere, although `boiler` sorts before `tanks`.
    let tanks = html.find("<h2>Channel <code>tanks</code>").unwrap();
    let boiler = html.find("<h2>Channel <code>boiler</code>").unwrap();
    assert!(tanks < boiler);
    assert!(html.contains("<nav><a href=\"#ch-0\">tanks</a><a href=\"#ch-1\">boiler</a></nav>"));
    assert!(section(&html, "tanks").starts_with("<section id=\"ch-0\">"));

    // Innovations by output name, in raw units, one figure per unit.
    let tanks = section(&html, "tanks");
    assert!(!html.contains("ε_k["), "no output indices");
    let innovation = figures(tanks, "innovation");
    assert_eq!(innovation.len(), 2, "cm and m³/h");
    assert!(innovation[0].contains(">LI201<") && innovation[0].contains("[cm]"));
    assert!(innovation[1].contains(">FI301<") && innovation[1].contains("[m³/h]"));
    assert!(
        tanks.contains("drawn times its scale"),
        "the conversion is said"
    );

    // θ̂ by unit: the level bias in cm, the outflow and feed biases in m³/h, with the
    // episode's θ̂ drawn over the window's.
    let magnitude = figures(tanks, "magnitude");
    assert_eq!(magnitude.len(), 2, "cm and m³/h");
    assert!(magnitude[0].contains("θ̂ [cm]") && magnitude[0].contains(">LI201_bias<"));
    assert!(!magnitude[0].contains("FIC101_bias"));
    assert!(magnitude[1].contains("θ̂ [m³/h]"));
    assert!(magnitude[1].contains(">FI301_bias<") && magnitude[1].contains(">FIC101_bias<"));
    assert!(magnitude[0].contains("class=\"episode-magnitude\""));
    assert!(
        tanks.contains("LI201_bias=") && tanks.contains(" cm,"),
        "alarm table units"
    );

    // The quiet channel: its output's name and unit, no θ̂ figure, legend or index.
    let boiler = section(&html, "boiler");
    let innovation = figures(boiler, "innovation");
    assert_eq!(innovation.len(), 1);
    assert!(innovation[0].contains(">TI101<") && innovation[0].contains("[°C]"));
    assert!(figures(boiler, "magnitude").is_empty());
    assert!(!boiler.contains("TI101_bias"), "no θ̂ legend");
    assert!(!boiler.contains("θ̂["));
    assert!(boiler.contains("No alarm on this channel"));
}

/// Without `y_units` (what `glrmon identify` writes) a level and a flow are not drawn
/// on one axis: each output whose unit is not given has an innovation figure of its own.
#[test]
fn outputs_of_unknown_units_are_not_put_on_one_axis() {
    let text = PLANT.replace("y_units = [\"cm\", \"m³/h\"]\n", "");
    assert_ne!(text, PLANT);
    let html = page_of(&text);
    let tanks = section(&html, "tanks");
    let innovations = figures(tanks, "innovation");
    assert_eq!(
        innovations.len(),
        2,
        "one figure per output of unknown unit"
    );
    assert!(
        innovations[0].contains("raw units of LI201"),
        "{}",
        innovations[0]
    );
    assert!(
        innovations[1].contains("raw units of FI301"),
        "{}",
        innovations[1]
    );
}
