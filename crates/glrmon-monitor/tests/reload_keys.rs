//! The settings a reload may change are named twice, once per side of one contract:
//! as configuration keys (`glrmon_spec::RELOADABLE_GLR_KEYS`, which a reload accepts
//! without a restart) and as the monitor's `Tuning` (what a reload applies). This
//! test holds the two together: each key, changed alone, is accepted and changes the
//! `Tuning`; every field of `Tuning` is changed by some key.

use glrmon_monitor::Tuning;
use glrmon_spec::RELOADABLE_GLR_KEYS;

const BASE: &str = r#"
[[channels]]
name = "tank"
model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]
[channels.glr]
window = 20
"#;

/// The `[channels.glr]` lines that change `key` from its default.
fn changed(key: &str) -> &'static str {
    match key {
        "threshold" => "threshold = 21.5\n",
        "false_alarm" => "false_alarm = 1e-6\n",
        "threshold_mode" => "threshold_mode = \"chi2\"\n",
        "calibrated" => {
            "[channels.glr.calibrated]\nthreshold = 12.5\nmtbfa = 10000.0\nsamples = 100000\n\
             episodes = 10\ninterval = [12.0, 13.0]\nsource = \"a.csv\"\n\
             isolation = { level_bias = 7.5 }\n"
        }
        "hysteresis" => "hysteresis = 0.3\n",
        "clear_samples" => "clear_samples = 4\n",
        "episode_end" => "episode_end = \"below_threshold\"\n",
        "gone_alpha" => "gone_alpha = 0.05\n",
        "gone_samples" => "gone_samples = 7\n",
        "isolation_law" => "isolation_law = \"chi2\"\n",
        "isolation_delay" => "isolation_delay = 7\n",
        "isolation_alpha" => "isolation_alpha = 0.05\n",
        other => panic!("a reloadable key this test does not know: {other}; add it"),
    }
}

fn tuning(text: &str) -> (glrmon_spec::Config, Tuning) {
    let cfg = glrmon_spec::parse(text).unwrap();
    let tuning = Tuning::from_channel(&cfg.channels[0]);
    (cfg, tuning)
}

#[test]
fn each_reloadable_key_changes_the_tuning_and_needs_no_restart() {
    let (base_cfg, base) = tuning(BASE);
    let mut fields_changed = [false; 8];
    for key in RELOADABLE_GLR_KEYS {
        let (cfg, t) = tuning(&format!("{BASE}{}", changed(key)));
        assert!(
            base_cfg.restart_needed(&cfg).is_empty(),
            "{key}: {:?}",
            base_cfg.restart_needed(&cfg)
        );
        assert_ne!(t, base, "changing {key} leaves the tuning as it was");
        for (seen, differs) in fields_changed.iter_mut().zip([
            t.alarm.threshold != base.alarm.threshold,
            t.alarm.hysteresis != base.alarm.hysteresis,
            t.alarm.clear_samples != base.alarm.clear_samples,
            t.episode_end != base.episode_end,
            t.isolation_delay != base.isolation_delay,
            t.isolation_alpha != base.isolation_alpha,
            t.isolation_onsets != base.isolation_onsets,
            t.isolation_thresholds != base.isolation_thresholds,
        ]) {
            *seen |= differs;
        }
    }
    assert_eq!(fields_changed, [true; 8], "a Tuning field no key reaches");
    // Every field of Tuning is in the list above: this fails to compile when one is
    // added without it.
    let Tuning {
        alarm: _,
        episode_end: _,
        isolation_delay: _,
        isolation_alpha: _,
        isolation_onsets: _,
        isolation_thresholds: _,
    } = base;
    // A key outside the list needs a restart.
    let (window, _) = tuning(&BASE.replace("window = 20", "window = 30"));
    assert!(!base_cfg.restart_needed(&window).is_empty());
}
