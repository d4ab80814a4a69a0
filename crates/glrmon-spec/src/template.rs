//! The commented configuration template of `glrmon config init`: one channel with a
//! small model, a sensor bias and an actuator bias fault, and every optional section
//! and key present but commented out with its default (or, where there is none, an
//! example value).

/// The template, for a channel named `channel`. It parses and validates as it is
/// (tested); uncomment a line to change a default.
///
/// ```
/// let text = glrmon_spec::template::config_template("tank");
/// let cfg = glrmon_spec::parse(&text).unwrap();
/// assert_eq!(cfg.channels[0].fault_names, ["level_bias", "valve_bias"]);
/// ```
#[must_use]
pub fn config_template(channel: &str) -> String {
    let name = toml::Value::String(channel.to_owned()).to_string();
    let key = toml::Value::String(format!("plant/{channel}")).to_string();
    TEMPLATE
        .replace("\"@NAME@\"", &name)
        .replace("\"@KEY@\"", &key)
}

const TEMPLATE: &str = r#"# glrmon configuration. Reference of every key: docs/CONFIG.md; JSON Schema for
# editors: `glrmon config schema > glrmon.schema.json`. Check it: `glrmon validate --config FILE`.
# Commented lines show each optional key with its default (or an example where none).
#
# The model (Zhang & Basseville 2014, eq. (1)), n states, l inputs, p outputs:
#   X_{k+1} = F X_k + G U_k + W_k + Psi_k(r) theta      cov(W) = Q
#   Y_k     = H X_k + J U_k + V_k + Phi_k(r) theta      cov(V) = R
# Matrices are written row by row: [[1.0, 0.0]] is 1x2; a number s means s*I.
# The state equation may be written in continuous time instead, dx/dt = A x + B u + w
# (A, B, Qc for F, G, Q; discretised with the channel's period, see [channels.model]).

# [zenoh]                            # Zenoh session (glrmon run, watch, status)
# config = "zenoh.json5"             # a Zenoh JSON5 file; default: none
# mode = "peer"                      # peer | client | router
# connect = []                       # e.g. ["tcp/127.0.0.1:7447"]
# listen = []                        # e.g. ["tcp/0.0.0.0:7447"]
# multicast_scouting = false

# [daemon]                           # glrmon run
# workers = 4                        # default: available cores
# worker_queue = 4096                # payloads per worker queue
# worker_queue_mb = 64.0             # MiB per worker queue
# intake_mb = 256.0                  # MiB of all worker queues
# output_queue = 16384               # records
# stat_every = 10                    # one stat record in this many samples; 0: none
# max_payload_bytes = 1048576
# shutdown_timeout = 5.0             # seconds
# instance = "plant-a"               # default: <host>-<pid>
# shard = "0/2"                      # default: every channel
# metrics = "127.0.0.1:9464"         # Prometheus /metrics; default: none

# [recording]                        # MCAP recording of glrmon run
# enabled = false
# directory = "recordings"
# prefix = "glrmon"
# inputs = true
# stat_every = 1
# max_file_mb = 1024.0
# max_file_seconds = 3600.0
# max_total_mb = 10240.0             # default: no cap
# flush_seconds = 1.0
# chunk_kb = 1024
# compression = "zstd"               # zstd | none
# queue = 65536
#
# [recording.capture]                # inputs only around alarms; default: off
# before_seconds = 10.0
# after_seconds = 10.0

[[channels]]
name = "@NAME@"
# key = "@KEY@"                      # Zenoh key of the samples
# payload = "json"                   # json, cdr, sparkplug or raw (docs/WIRE.md)
# cdr = { message = "std_msgs/msg/Float64MultiArray" }  # with payload = "cdr"
# raw = { layout = ["t", "u0", "y0", "y1"] }              # with payload = "raw": f64 LE
# tags = { period = 0.1, hold = 3, time = "zenoh", keys = { u0 = "plant/u", y0 = { key = "plant/y", field = "value", time_field = "ts" } } }
#                                    # instead of key: one key per signal (docs/WIRE.md);
#                                    # trigger = "y0" instead of period: a sample per y0
# topics = { trigger = "y0", keys = { u0 = { key = "/plant/u", field = "data.0" }, y0 = { key = "/plant/y", field = "data.0" } } }
#                                    # glrmon replay of a ROS 2 bag or Foxglove MCAP
# period = 0.1                       # seconds; required with A (continuous time)
# signals = 0                        # scheduling signals p0...; default: highest used + 1

[channels.model]                     # n = 2 states, l = 1 input, p = 2 outputs
F = [[0.9, 0.1], [0.0, 0.8]]
G = [[0.0], [1.0]]
H = [[1.0, 0.0], [0.0, 1.0]]
# J = [[0.0], [0.0]]                 # default: zero
Q = 0.01                             # 0.01 * I
R = 0.04
# E = [[1.0], [0.0]]                 # unknown input (n x q, q < p); default: none
# Fd = [[0.0], [0.0]]                # its effect on the outputs (p x q; parity only)
# S = [[0.0, 0.0], [0.0, 0.0]]       # cov(W, V) (n x p); default: none
# x0 = [0.0, 0.0]                    # default: zeros
# P0 = 1.0                           # default: I
# An LPV matrix: F = { base = [[0.9, 0.1], [0.0, 0.8]], p0 = [[0.0, 0.0], [0.0, 0.1]] }
# In continuous time instead of F, G, Q (needs period; F = e^(A*T), G, Q computed):
# A = [[-1.0, 1.0], [0.0, -2.0]]     # 1/s
# B = [[0.0], [1.0]]                 # per second
# Qc = 0.1                           # noise intensity per second, 0.1 * I

# [channels.scaling]                 # model value = (raw - offset) / scale
# u_offset = [0.0]
# u_scale = [1.0]
# y_offset = [0.0, 0.0]
# y_scale = [1.0, 1.0]

# [channels.columns]                 # CSV column names; default u0, y0, y1, ...
# u = ["valve"]
# y = ["level", "flow"]
# p = []
# u_units = ["%"]                    # raw units, shown in reports; default: none
# y_units = ["cm", "m3/h"]
# p_units = []

[[channels.faults]]
name = "level_bias"
kind = "sensor_bias"                 # Phi = e_0
output = 0
# onset = "step"                     # step | impulse | ramp | known

[[channels.faults]]
name = "valve_bias"
kind = "actuator_bias"               # Psi = G e_0
input = 0

# Other faults:
# [[channels.faults]]
# name = "valve_gain"
# kind = "actuator_gain"             # also sensor_drift (output = j, a ramp)
# input = 0
#
# [[channels.faults]]                # explicit signature columns
# name = "leak"
# psi = [0.0, "-0.1*u0[-1]"]         # state column: n numbers or expressions
# phi = [0.0, 0.0]                   # output column: p entries
# onset = "step"
#
# [[channels.faults]]
# kind = "all_sensors"               # one sensor_bias per output (all_actuators: per input)

# [channels.glr]
# window = 100                       # w
# min_lag = 1                        # s
# threshold = 20.0                   # explicit lambda; default: from false_alarm
# false_alarm = 1e-4                 # per sample
# threshold_mode = "bonferroni"      # bonferroni | chi2
# detector = "glr"                   # glr | chi2 | cusum | parity | fdf | uio | rls | kernel
# hysteresis = 0.1
# clear_samples = 1
# episode_end = "fault_gone"         # fault_gone | below_threshold
# gone_alpha = 0.01
# gone_samples = 200                 # default: 2w
# isolation_delay = 2                # default: n
# isolation_alpha = 0.01
# isolation_law = "bonferroni"       # bonferroni | chi2
# rank_tolerance = 1e-9
# max_gap = 100
# max_reorder = 16
# settle = 100                       # after a restart; default: w
# warm_up = "window"                 # or a number of samples; default: none
#
# [[channels.glr.groups]]
# name = "valve"
# faults = ["valve_bias"]
#
# [channels.glr.calibrated]          # written by `glrmon calibrate --write`
# threshold = 18.2
# mtbfa = 100000.0                   # or sample_far = 1e-4
# sample_far = 1e-4
# samples = 1000000
# episodes = 9
# exceedances = 120
# interval = [17.5, 19.0]
# source = "recordings/fault-free.mcap"
# isolation = { level_bias = 6.1, valve_bias = 5.9 }

# [channels.cusum]                   # detector = "cusum" (docs/DETECTORS.md)
# magnitudes = [0.5]                 # one per fault: the size each CUSUM is tuned for
#
# [channels.parity]                  # detector = "parity"
# order = 2                          # default: the smallest with a parity space
# evaluation = "chi2"                # chi2 | energy (then give glr.threshold)
# energy_window = 10
#
# [channels.observer]                # detector = "fdf" or "uio"
# L = [[0.5, 0.0], [0.0, 0.5]]       # fdf gain (n x p); default: the optimal one
# V = [[1.0, 0.0], [0.0, 1.0]]       # fdf residual weight; default: optimal
# evaluation = "chi2"                # chi2 | energy
# energy_window = 10
#
# [channels.rls]                     # detector = "rls" (needs an exciting input)
# forgetting = 0.99
# p0 = 1000.0
# excitation = 1e-6
# evaluation = "chi2"                # chi2 | energy
# energy_window = 10
#
# [channels.kernel]                  # detector = "kernel" (model.A, B with period)
# E = [[1.0], [0.0]]                 # fault channels (n x p*), required
# output_noise = 0.05                # bound on |d_y|; default 0
# state_noise = 0.0                  # bound on |d_x|; default 0
# floor = 1e-3                       # added to the thresholds; default 0
# rates = [1.0]                      # one per state of n - p*; default 1, 2, ...
# omega_bar = 2.5
# order = 1                          # N; default n - p*
# detection_rate = 1.0               # omega
# activation = 0.7                   # default: 0.7 x its limit for the rates
# rearm = 5.0                        # seconds below 1 before a new episode
#
# [[channels.kernel.candidates]]     # candidate fault functions; faults = candidates
# name = "stuck"
# lipschitz = 1.0
# f = ["x0"]                         # one per column of E, of x<i>, u<i>, t

# [channels.simulation]              # glrmon simulate; expressions of k
# inputs = ["sin(0.05*k)"]           # default: 0
# signals = []
# unknown_input = []                 # one per column of E
#
# [channels.simulation.controller]   # PI loop; default: open loop
# output = 0
# input = 0
# setpoint = 1.0
# kp = 0.5
# ki = 0.05

# [channels.diagnosis]               # sparse diagnosis (Zhang 2021) at alarms
# enabled = false
# residual = "kalman"                # kalman | kitanidis (default with E)
# span = 200                         # default: r-hat to the alarm
# history = 200                      # default: 2 * window
# alpha = 0.01
#
# [channels.diagnosis.lasso]
# path_points = 100
# ratio = 1e-4
# plateau_scale = "log"              # log | linear (the paper's Table II; may miss a small fault)

# [channels.consistency]             # model-consistency test
# enabled = true
# window = 500
# alpha = 1e-6
"#;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_template_validates_and_quotes_the_name() {
        let cfg = crate::parse(&config_template("pump \"3\"")).unwrap_err();
        // A name with a space is refused by validation, not by TOML.
        assert!(cfg.to_string().contains("name"), "{cfg}");
        let cfg = crate::parse(&config_template("pump3")).unwrap();
        assert_eq!(cfg.channels[0].name, "pump3");
        assert_eq!(cfg.channels[0].key, "plant/pump3");
        assert!(cfg.warnings.is_empty(), "{:?}", cfg.warnings);
    }

    /// Every key of the JSON Schema is in the template, set or commented out.
    #[test]
    fn the_template_shows_every_key_of_the_schema() {
        let schema: serde_json::Value = serde_json::from_str(&crate::json_schema()).unwrap();
        let text = config_template("tank");
        let mut missing = Vec::new();
        let mut defs: Vec<&serde_json::Value> = vec![&schema];
        defs.extend(schema["definitions"].as_object().unwrap().values());
        for def in defs {
            if let Some(props) = def.get("properties").and_then(|p| p.as_object()) {
                for key in props.keys() {
                    let as_key = format!("{key} =");
                    let as_table = format!(".{key}]");
                    let top = format!("[{key}]");
                    if !(text.contains(&as_key) || text.contains(&as_table) || text.contains(&top))
                    {
                        missing.push(key.clone());
                    }
                }
            }
        }
        assert!(missing.is_empty(), "not in the template: {missing:?}");
    }
}
