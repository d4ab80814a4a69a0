//! docs/CONFIG.md is what the generator writes: a change of the configuration types'
//! doc comments, defaults or limits, or of the template, without `make config-doc`
//! fails here.

#[test]
fn docs_config_md_is_up_to_date() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/CONFIG.md");
    let on_disk = std::fs::read_to_string(path).unwrap_or_default();
    let generated = glrmon_spec::reference::config_reference();
    if on_disk != generated {
        let line = on_disk
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or_else(|| on_disk.lines().count().min(generated.lines().count()));
        panic!(
            "docs/CONFIG.md differs from the generator from line {}: run `make config-doc`\n\
             on disk:   {:?}\ngenerated: {:?}",
            line + 1,
            on_disk.lines().nth(line),
            generated.lines().nth(line)
        );
    }
}

#[test]
fn the_reference_covers_every_section_and_key() {
    let text = glrmon_spec::reference::config_reference();
    let schema: serde_json::Value = serde_json::from_str(&glrmon_spec::json_schema()).unwrap();
    for (name, def) in schema["definitions"].as_object().unwrap() {
        if let Some(props) = def["properties"].as_object() {
            for key in props.keys() {
                assert!(
                    text.contains(&format!("| `{key}` |")),
                    "{name}.{key} has no row in the reference"
                );
            }
        }
    }
    for topic in [
        "## Faults",
        "sensor_bias",
        "actuator_gain",
        "all_sensors",
        "all_actuators",
        "Onsets",
        "Unknown inputs (`model.E`)",
        "[channels.scaling]",
        "[channels.columns]",
        "## Expressions",
        "`u0[-1]`",
        "Matrix syntax",
        "## Limits",
    ] {
        assert!(text.contains(topic), "no {topic}");
    }
}
