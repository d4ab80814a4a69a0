//! Alarms kept for readers that were away, after the instance that raised them is gone:
//! `zenohd` with the shipped deploy/zenohd-history.json5 (its storage manager plugin,
//! memory volume; `make deps-zenohd` builds both), a `glrmon run` instance in client
//! mode, a plant publisher, explicit tcp/127.0.0.1 endpoints.
//!
//! Asserts: the instance's alarm, received live, is returned by a plain Zenoh `get` on
//! `glrmon/*/alarm` after the instance was killed, byte for byte; `glrmon watch --since
//! 1h` started after the kill prints it, as stored (a storage keeps the record, not the
//! attachment that names its instance).

#[path = "support.rs"]
mod support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use glrmon_wire::encode_sample;
use zenoh::Wait as _;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_storage_keeps_the_alarms_of_an_instance_that_is_gone() {
    let zenohd = support::zenohd_binary()
        .expect("zenohd is not installed: `make deps-zenohd` builds it and its storage plugin");
    let plugin = zenohd
        .parent()
        .unwrap()
        .join("libzenoh_plugin_storage_manager.so");
    assert!(
        plugin.exists() || Path::new("/usr/local/lib/libzenoh_plugin_storage_manager.so").exists(),
        "{} is missing: `make deps-zenohd` builds it",
        plugin.display()
    );
    let dir = support::Scratch::new("alarm-history");
    let port = support::free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/zenohd-history.json5"),
    )
    .unwrap()
    .replace(":7447", &format!(":{port}"));
    let router_cfg = dir.0.join("router.json5");
    std::fs::write(&router_cfg, text).unwrap();
    let mut router = Command::new(&zenohd)
        .arg("--config")
        .arg(&router_cfg)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let _router = support::KillOnDrop(router.id());
    let t = std::time::Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "zenohd not listening"
        );
        assert!(router.try_wait().unwrap().is_none(), "zenohd exited");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    let channel_cfg =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let mut cmd = support::glrmon();
    cmd.args(["run", "--config"]).arg(&channel_cfg).args([
        "--instance",
        "hist-a",
        "--mode",
        "client",
        "--connect",
        &endpoint,
    ]);
    let (mut instance, log) = support::spawn_logged(&mut cmd);
    let _instance = support::KillOnDrop(instance.id());
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(instance.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    assert!(
        line.contains("monitoring 1 channel(s)"),
        "{line}{}",
        log.lock().unwrap()
    );

    // The plant: an actuator bias from k = 200; the alarm received live.
    let session = support::client(&endpoint).await;
    let alarms = session.declare_subscriber("glrmon/*/alarm").await.unwrap();
    let cfg = glrmon_spec::load(&channel_cfg).unwrap();
    let mut sim = glrmon_sim::faulty_simulator(
        &cfg.channels[0],
        11,
        &[("actuator_bias".to_owned(), 0.5)],
        200,
    )
    .unwrap();
    let publisher = support::matched_publisher(&session, "plant/dc_motor").await;
    let mut bytes = Vec::new();
    for s in support::wire_samples(&mut sim, 0, 400) {
        bytes.clear();
        encode_sample("dc_motor", &s, &mut bytes).unwrap();
        publisher.put(bytes.clone()).wait().unwrap();
    }
    let live = tokio::time::timeout(Duration::from_secs(10), alarms.recv_async())
        .await
        .expect("the alarm")
        .unwrap();
    let alarm = live.payload().to_bytes().into_owned();

    // The instance goes, with its own cache.
    instance.kill().unwrap();
    let _ = instance.wait();
    tokio::time::sleep(Duration::from_millis(300)).await;

    // A plain get still has the alarm, from the router's storage.
    let replies = session
        .get("glrmon/*/alarm")
        .timeout(Duration::from_secs(5))
        .await
        .unwrap();
    let mut stored = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.into_result() {
            stored.push((
                sample.key_expr().to_string(),
                sample.payload().to_bytes().into_owned(),
            ));
        }
    }
    assert_eq!(
        stored,
        vec![("glrmon/dc_motor/alarm".to_owned(), alarm.clone())],
        "{}",
        String::from_utf8_lossy(&alarm)
    );

    // So does `glrmon watch --since`, which flags its instance as gone.
    let out = support::run_ok(support::glrmon().args([
        "watch",
        "glrmon/*/alarm",
        "--since",
        "1h",
        "--count",
        "1",
        "--mode",
        "client",
        "--connect",
        &endpoint,
    ]));
    let printed = String::from_utf8_lossy(&out.stdout);
    assert!(printed.contains("dc_motor"), "{printed}");
    // (The storage keeps the record, not its Zenoh attachment.)
    assert!(
        printed.contains("[stored by a Zenoh storage, which keeps no source]"),
        "{printed}"
    );
    drop((alarms, publisher));
    session.close().await.unwrap();
    let _ = router.kill();
    let _ = router.wait();
}
