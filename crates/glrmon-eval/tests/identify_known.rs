//! A known system through the whole chain: recordings in raw units of a
//! 4-state, 2-input, 3-output innovation model with coloured noise (poles 0.9,
//! 0.7 ± 0.2i, 0.5) → [`identify_channel`] → threshold calibrated on the same recordings
//! → a monitor of the identified model on fresh data, next to the true model's monitor
//! calibrated the same way: the identified poles are the true ones, the false-alarm
//! rate on fresh fault-free data is the one calibrated for, and sensor and actuator
//! biases are detected with delays close to the true model's.

use glrmon_core::threshold::calibration::{Target, count_episodes};
use glrmon_eval::calibrate::{Statistics, calibrate_channel, recorded};
use glrmon_eval::identify::{IdentifyRequest, identify_channel};
use glrmon_ident::IdentSettings;
use glrmon_spec::Channel;
use glrmon_wire::{Record, Sample};

/// The true plant, in innovation form (Q = K·Re·Kᵀ, S = K·Re, R = Re), published in raw
/// units around an operating point; `controller` closes the loop u0 ← y0.
fn truth(controller: bool) -> Channel {
    let k = [
        [0.3, 0.0, 0.0],
        [0.0, 0.2, 0.0],
        [0.0, 0.0, 0.2],
        [0.1, 0.0, 0.1],
    ];
    let re = [[0.5, 0.1, 0.0], [0.1, 0.4, 0.05], [0.0, 0.05, 0.3]];
    let mul = |a: &[[f64; 3]], b: &[[f64; 3]; 3]| -> Vec<[f64; 3]> {
        a.iter()
            .map(|r| std::array::from_fn(|j| (0..3).map(|i| r[i] * b[i][j]).sum()))
            .collect()
    };
    let s = mul(&k, &re);
    let q: Vec<Vec<f64>> = s
        .iter()
        .map(|si| {
            k.iter()
                .map(|kj| (0..3).map(|i| si[i] * kj[i]).sum())
                .collect()
        })
        .collect();
    let rows = |m: &[Vec<f64>]| {
        let r: Vec<String> = m.iter().map(|r| format!("{r:?}")).collect();
        format!("[{}]", r.join(", "))
    };
    let s: Vec<Vec<f64>> = s.iter().map(|r| r.to_vec()).collect();
    let loop_ = if controller {
        "controller = { output = 0, input = 0, setpoint = 10.0, kp = 0.2, ki = 0.02 }\n"
    } else {
        ""
    };
    let text = format!(
        r#"
[[channels]]
name = "plant"
[channels.model]
F = [[0.9, 0.0, 0.0, 0.0], [0.0, 0.7, 0.2, 0.0], [0.0, -0.2, 0.7, 0.0], [0.0, 0.0, 0.0, 0.5]]
G = [[1.0, 0.0], [0.5, 1.0], [0.0, 0.8], [1.0, -0.5]]
H = [[1.0, 0.5, 0.0, 0.3], [0.0, 1.0, 0.4, 0.0], [0.2, 0.0, 1.0, 1.0]]
J = [[0.1, 0.0], [0.0, 0.2], [0.0, 0.0]]
Q = {q}
R = [[0.5, 0.1, 0.0], [0.1, 0.4, 0.05], [0.0, 0.05, 0.3]]
S = {s}
P0 = 1e-9
[channels.scaling]
u_offset = [2.0, -1.0]
u_scale = [0.5, 2.0]
y_offset = [10.0, -5.0, 100.0]
y_scale = [2.0, 0.5, 10.0]
[channels.simulation]
inputs = ["2 + 0.5 * normal(0, 1)", "-1 + 2 * normal(0, 1)"]
{loop_}
[[channels.faults]]
kind = "all_sensors"
[[channels.faults]]
kind = "all_actuators"
[channels.glr]
window = 50
warm_up = "window"
"#,
        q = rows(&q),
        s = rows(&s),
    );
    glrmon_spec::parse(&text).unwrap().channels[0].clone()
}

fn simulate(
    channel: &Channel,
    n: usize,
    seed: u64,
    fault: Option<(&str, f64, u64)>,
) -> Vec<Sample> {
    let mut sim = glrmon_sim::from_channel(channel, seed).unwrap();
    if let Some((name, theta, onset)) = fault {
        let magnitude = glrmon_sim::fault_magnitudes(channel, &[name.into()], &[theta]).unwrap();
        sim = glrmon_sim::inject(sim, channel, glrmon_sim::Injection { magnitude, onset }).unwrap();
    }
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

fn csv(samples: &[Sample]) -> String {
    let mut text = String::from("k,u0,u1,y0,y1,y2\n");
    for s in samples {
        text.push_str(&format!(
            "{},{:?},{:?},{:?},{:?},{:?}\n",
            s.k.unwrap(),
            s.u[0],
            s.u[1],
            s.y[0],
            s.y[1],
            s.y[2]
        ));
    }
    text
}

/// l_k per sample (NaN where none) and the alarms' samples.
fn monitor(channel: &Channel, samples: &[Sample]) -> (Vec<f64>, Vec<u64>) {
    let mut mon = glrmon_monitor::Monitor::from_channel(channel).unwrap();
    let (mut records, mut glr, mut alarms) = (Vec::new(), Vec::new(), Vec::new());
    for s in samples {
        mon.on_sample(s, &mut records);
        for r in records.drain(..) {
            match r {
                Record::Stat(s) => glr.push(s.glr.unwrap_or(f64::NAN)),
                Record::Alarm(a) => alarms.push(a.k),
                _ => {}
            }
        }
    }
    (glr, alarms)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn chain(controller: bool) {
    let label = if controller {
        "closed loop"
    } else {
        "open loop"
    };
    let mut truth = truth(controller);
    let dir = std::env::temp_dir().join(format!(
        "glrmon-identify-known-{}-{controller}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let files: Vec<_> = (1..=3)
        .map(|seed| {
            let path = dir.join(format!("run{seed}.csv"));
            std::fs::write(&path, csv(&simulate(&truth, 10_000, seed, None))).unwrap();
            path
        })
        .collect();
    let identified = identify_channel(&IdentifyRequest {
        channel: "plant".into(),
        files: files.clone(),
        inputs: None,
        outputs: None,
        settings: IdentSettings::default(),
        window: 50,
        topics: None,
        notes: vec![],
    })
    .unwrap();
    let mut model = glrmon_spec::parse(&identified.config).unwrap().channels[0].clone();
    let id = &identified.identification;
    let poles = glrmon_ident::sorted_eigenvalues(&id.model.a);
    let true_poles = [(0.9, 0.0), (0.7, 0.2), (0.7, -0.2), (0.5, 0.0)];
    println!(
        "{label}: order {} ({}), poles {poles:.4?}, Σ = Re to {:.1e}",
        id.model.order(),
        id.order.reason,
        identified.sigma_mismatch
    );
    assert_eq!(id.model.order(), 4, "{label}: {}", id.order.reason);
    for (t_re, t_im) in true_poles {
        let nearest = poles
            .iter()
            .map(|p| ((p.re - t_re).powi(2) + (p.im - t_im).powi(2)).sqrt())
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest < 0.03,
            "{label}: no pole within 0.03 of {t_re}{t_im:+}i: {poles:?}"
        );
    }

    // Thresholds for one false-alarm episode per 500 samples, on the recordings.
    for channel in [&mut truth, &mut model] {
        let mut stats = Statistics::default();
        for f in &files {
            stats.append(recorded(channel, f, None).unwrap());
        }
        let cal = calibrate_channel(channel, stats, Target::Mtbfa(500.0)).unwrap();
        channel.alarm.threshold = cal.alarm.threshold;
    }
    // Fresh fault-free data: 60 000 samples, 120 episodes expected. The threshold was
    // found on 30 000 samples (60 episodes, ±13 % on the rate at 1σ, and l_k's
    // episodes cluster): a band of a factor 1.6 each way.
    let fresh = simulate(&truth, 60_000, 77, None);
    for (name, channel) in [("true", &truth), ("identified", &model)] {
        let (glr, _) = monitor(channel, &fresh);
        let episodes = count_episodes(&glr, channel.alarm);
        println!(
            "{label}: {name} model, λ = {:.2}: {episodes} episodes in 60 000 fresh samples (120 expected)",
            channel.alarm.threshold
        );
        assert!(
            (75..=190).contains(&episodes),
            "{label}: {name}: {episodes} episodes"
        );
    }

    // Biases from k = 200 in raw units, 30 runs each: detection rate and median delay.
    for (fault, theta) in [("y1_bias", 1.0), ("y2_bias", 10.0), ("u1_bias", 2.0)] {
        let mut delays = [Vec::new(), Vec::new()];
        for seed in 0..30 {
            let run = simulate(&truth, 400, 1000 + seed, Some((fault, theta, 200)));
            for (d, channel) in delays.iter_mut().zip([&truth, &model]) {
                let (_, alarms) = monitor(channel, &run);
                if let Some(k) = alarms.iter().find(|&&k| k >= 200) {
                    d.push((k - 200) as f64);
                }
            }
        }
        let [t, m] = delays;
        let (nt, nm) = (t.len(), m.len());
        let (dt, dm) = (median(t), median(m));
        println!(
            "{label}: {fault} θ = {theta}: detected true {nt}/30 (median delay {dt}), identified {nm}/30 (median delay {dm})"
        );
        assert!(nm >= 27 && nt >= 27, "{label}: {fault}: {nt}, {nm} of 30");
        assert!(
            dm <= dt + 2.0_f64.max(0.5 * dt),
            "{label}: {fault}: delay {dm} vs {dt}"
        );
    }
}

#[test]
fn known_system_open_loop() {
    chain(false);
}
