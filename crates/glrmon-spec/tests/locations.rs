//! Errors carry the line and column of the offending key, and unknown keys, names and
//! keywords get a "did you mean" when a valid one is close (and none when nothing is).

use glrmon_spec::{Location, Problem};

mod common;
use common::{BASE, with};

fn problems(text: &str) -> Vec<Problem> {
    match glrmon_spec::parse(text) {
        Ok(_) => panic!("expected errors for:\n{text}"),
        Err(e) => e.errors,
    }
}

/// The only problem of `text`, which must contain `expected`.
fn only(text: &str, expected: &str) -> Problem {
    let p = problems(text);
    assert_eq!(p.len(), 1, "{p:#?}");
    assert!(
        p[0].to_string().contains(expected),
        "wanted «{expected}» in {p:#?}"
    );
    p[0].clone()
}

/// The problem of `text` that contains `expected`.
fn find(text: &str, expected: &str) -> Problem {
    let p = problems(text);
    p.iter()
        .find(|p| p.to_string().contains(expected))
        .unwrap_or_else(|| panic!("wanted «{expected}» in {p:#?}"))
        .clone()
}

fn at(line: usize, column: usize) -> Option<Location> {
    Some(Location { line, column })
}

#[test]
fn a_psi_of_the_wrong_length_points_at_psi() {
    let p = only(
        &with("psi = [\"0.5*u0\", 1.0]", "psi = [\"0.5*u0\", 1.0, 2.0]"),
        r#"channels[0] "pump3": faults[1].psi"#,
    );
    assert_eq!(p.location, at(19, 1), "{p}");
    assert!(
        p.in_file("plant.toml")
            .starts_with(r#"plant.toml:19:1: channels[0] "pump3": faults[1].psi"#),
        "{}",
        p.in_file("plant.toml")
    );
    // Display is the path and message alone, as before locations.
    assert!(
        p.to_string()
            .starts_with(r#"channels[0] "pump3": faults[1].psi"#),
        "{p}"
    );
}

#[test]
fn a_matrix_of_the_wrong_shape_points_at_its_letter() {
    let p = only(
        &with("H = [[1.0, 0.0]]", "H = [[1.0, 0.0, 0.0]]"),
        "model.F is 2×2 but H has 3 columns",
    );
    // The error is about F (its path), which is on line 6.
    assert_eq!(p.location, at(6, 1), "{p}");
}

#[test]
fn glr_and_fault_fields_point_at_their_key_in_its_table() {
    let p = only(
        &with("window = 50", "window = 50\nhysteresis = 1.5"),
        "glr.hysteresis",
    );
    assert_eq!(p.location, at(23, 1), "{p}");
    let p = only(&with("input = 0", "input = 4"), "faults[0].input");
    assert_eq!(p.location, at(15, 1), "{p}");
}

#[test]
fn inline_tables_and_arrays_are_located_too() {
    let text = "\n[[channels]]\nname = \"a\"\nmodel = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }\n\
                faults = [{ name = \"b\", kind = \"sensor_bias\", output = 0 },\n  \
                { name = \"c\", psi = [1.0, 2.0] }]\n";
    let p = only(text, "faults[1].psi");
    assert_eq!(p.location, at(6, 17), "{p}");
}

#[test]
fn a_duplicate_channel_points_at_the_second_name() {
    let text = format!(
        "{BASE}\n{}",
        BASE.replace("[channels.glr]\nwindow = 50\nmin_lag = 1\n", "")
    );
    let p = problems(&text);
    let dup = p
        .iter()
        .find(|p| p.message.contains("duplicate channel name"))
        .unwrap();
    assert_eq!(dup.location, at(27, 1), "{dup}");
}

#[test]
fn an_unknown_key_is_located_with_a_suggestion() {
    let p = only(&with("window = 50", "windw = 50"), "unknown field `windw`");
    assert_eq!(p.location, at(22, 1), "{p}");
    assert!(p.message.ends_with("; did you mean `window`?"), "{p}");
    // Nothing close: no suggestion.
    let p = only(
        &with("name = \"pump3\"", "name = \"pump3\"\ncolour = 3"),
        "unknown field `colour`",
    );
    assert_eq!(p.location, at(4, 1), "{p}");
    assert!(!p.message.contains("did you mean"), "{p}");
}

#[test]
fn unknown_kinds_onsets_and_fault_names_get_suggestions() {
    let p = only(
        &with("kind = \"actuator_bias\"", "kind = \"actuator_bais\""),
        "did you mean \"actuator_bias\"?",
    );
    assert_eq!(p.location, at(14, 1), "{p}");
    let p = only(
        &with("input = 0", "input = 0\nonset = \"stpe\""),
        "did you mean \"step\"?",
    );
    assert_eq!(p.location, at(16, 1), "{p}");
    let p = find(
        &with(
            "min_lag = 1",
            "min_lag = 1\ngroups = [{ name = \"g\", faults = [\"bais\"] }]",
        ),
        "unknown fault \"bais\"; did you mean \"bias\"?",
    );
    assert_eq!(p.location, at(24, 25), "{p}");
    // Nothing close: the list alone.
    let p = only(
        &with("kind = \"actuator_bias\"", "kind = \"valve\""),
        "is not one of custom",
    );
    assert!(!p.message.contains("did you mean"), "{p}");
    let p = find(
        &with(
            "min_lag = 1",
            "min_lag = 1\ngroups = [{ name = \"g\", faults = [\"leak\"] }]",
        ),
        "unknown fault \"leak\"",
    );
    assert!(!p.message.contains("did you mean"), "{p}");
}

#[test]
fn an_unknown_channel_name_gets_a_suggestion() {
    let cfg = glrmon_spec::parse(BASE).unwrap();
    let e = cfg.pick_channel(Some("pump")).unwrap_err().to_string();
    assert!(e.ends_with("; did you mean \"pump3\"?"), "{e}");
    let e = cfg.pick_channel(Some("boiler")).unwrap_err().to_string();
    assert!(!e.contains("did you mean"), "{e}");
}

#[test]
fn a_syntax_error_keeps_toml_s_own_rendering() {
    let p = only(
        &with("window = 50", "window = = 50"),
        "TOML parse error at line 22",
    );
    assert_eq!(p.location, None);
}
