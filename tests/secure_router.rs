//! The shipped secure router configuration (deploy/zenohd-secure.json5: mutual TLS,
//! access control by the certificate's common name) with its client side
//! (deploy/zenoh-client-tls.json5), their paths and port replaced by this test's. The
//! router is `zenohd` when installed, else a router-mode session of this process
//! reading the same file. A certificate authority and one certificate per role are made
//! here (rcgen).
//!
//! Asserts: a `glrmon run` instance (CN "glrmon") monitors a plant publisher (CN
//! "plant") and its alarm reaches a viewer (CN "viewer") with its source attached;
//! the same alarm record published again by the plant publisher and by the viewer, and
//! an alarm of a channel that does not exist, are refused by the router (the viewer
//! sees none of them, while the same put from a "glrmon" certificate passes); a
//! client whose certificate another authority signed cannot
//! open a session; `glrmon status` through the viewer's configuration lists the
//! instance.

#[path = "support.rs"]
mod support;

use std::io::BufRead as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use glrmon_wire::{Record, Source, encode_sample};
use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair};

/// A certificate authority that signs the test's certificates.
struct Authority {
    issuer: Issuer<'static, KeyPair>,
    pem: String,
}

impl Authority {
    fn new(name: &str) -> Self {
        let key = KeyPair::generate().unwrap();
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.distinguished_name.push(DnType::CommonName, name);
        let pem = params.self_signed(&key).unwrap().pem();
        Self {
            issuer: Issuer::new(params, key),
            pem,
        }
    }

    /// (certificate, key) in PEM for `common_name`, valid for localhost.
    fn sign(&self, common_name: &str) -> (String, String) {
        let key = KeyPair::generate().unwrap();
        let mut params =
            CertificateParams::new(vec!["localhost".to_owned(), "127.0.0.1".to_owned()]).unwrap();
        params
            .distinguished_name
            .push(DnType::CommonName, common_name);
        let cert = params.signed_by(&key, &self.issuer).unwrap();
        (cert.pem(), key.serialize_pem())
    }
}

/// The shipped file `deploy/<name>` with its /etc paths moved to `dir` and its port
/// to `port`, written to `dir/<out>`.
fn deployed(name: &str, dir: &Path, port: u16, replace: &[(&str, &str)], out: &str) -> PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../deploy")
            .join(name),
    )
    .unwrap();
    let mut text = text.replace(":7447", &format!(":{port}"));
    for (from, to) in replace {
        assert!(text.contains(from), "{name} has no {from}");
        text = text.replace(from, to);
    }
    let path = dir.join(out);
    std::fs::write(&path, text).unwrap();
    path
}

/// A client configuration for role `cn` with a certificate `authority` signed.
fn client_config(authority: &Authority, ca: &Path, cn: &str, dir: &Path, port: u16) -> PathBuf {
    let (cert, key) = authority.sign(cn);
    let (cert_path, key_path) = (dir.join(format!("{cn}.crt")), dir.join(format!("{cn}.key")));
    std::fs::write(&cert_path, cert).unwrap();
    std::fs::write(&key_path, key).unwrap();
    deployed(
        "zenoh-client-tls.json5",
        dir,
        port,
        &[
            ("/etc/glrmon/tls/ca.crt", ca.to_str().unwrap()),
            ("/etc/glrmon/tls/client.crt", cert_path.to_str().unwrap()),
            ("/etc/glrmon/tls/client.key", key_path.to_str().unwrap()),
        ],
        &format!("{cn}.json5"),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_secure_router_refuses_a_forged_alarm() {
    let scratch = support::Scratch::new("secure-router");
    let dir = scratch.0.clone();
    let port = support::free_port();
    let authority = Authority::new("glrmon test CA");
    let ca = dir.join("ca.crt");
    std::fs::write(&ca, &authority.pem).unwrap();
    let (router_cert, router_key) = authority.sign("router");
    std::fs::write(dir.join("router.crt"), router_cert).unwrap();
    std::fs::write(dir.join("router.key"), router_key).unwrap();
    let router_cfg = deployed(
        "zenohd-secure.json5",
        &dir,
        port,
        &[("/etc/zenoh/tls/", &format!("{}/", dir.display()))],
        "router.json5",
    );
    let router =
        support::Router::start_with(Some(&router_cfg), &format!("tls/127.0.0.1:{port}")).await;
    eprintln!("router: {}", router.kind());

    let open = |file: &Path| zenoh::Config::from_file(file).unwrap();
    let glrmon_cfg = client_config(&authority, &ca, "glrmon", &dir, port);
    let plant_cfg = client_config(&authority, &ca, "plant", &dir, port);
    let viewer_cfg = client_config(&authority, &ca, "viewer", &dir, port);

    // The instance, its channel the DC motor.
    let channel_cfg =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let mut cmd = support::glrmon();
    cmd.args(["run", "--config"])
        .arg(&channel_cfg)
        .args(["--instance", "secure-a", "--zenoh-config"])
        .arg(&glrmon_cfg);
    let (mut child, log) = support::spawn_logged(&mut cmd);
    let _instance = support::KillOnDrop(child.id());
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(
        line.contains("instance secure-a monitoring 1 channel(s)"),
        "{line}{}",
        log.lock().unwrap()
    );

    // The viewer watches every alarm.
    let viewer = zenoh::open(open(&viewer_cfg)).await.unwrap();
    let alarms = viewer.declare_subscriber("glrmon/*/alarm").await.unwrap();

    // The plant publishes a fault from k = 200.
    let plant = zenoh::open(open(&plant_cfg)).await.unwrap();
    let cfg = glrmon_spec::load(&channel_cfg).unwrap();
    let mut sim = glrmon_sim::faulty_simulator(
        &cfg.channels[0],
        7,
        &[("actuator_bias".to_owned(), 0.5)],
        200,
    )
    .unwrap();
    let publisher = glrmon_zenoh::plant_publisher(
        &plant,
        "plant/dc_motor",
        zenoh::bytes::Encoding::APPLICATION_JSON,
        100,
    )
    .await
    .unwrap();
    let t = Instant::now();
    while !publisher.matching_status().await.unwrap().matching() {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "the instance never subscribed through the router: {}",
            log.lock().unwrap()
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let mut bytes = Vec::new();
    for s in support::wire_samples(&mut sim, 0, 400) {
        bytes.clear();
        encode_sample("dc_motor", &s, &mut bytes).unwrap();
        publisher.put(bytes.clone()).await.unwrap();
    }

    // The real alarm arrives, naming its instance.
    let real = tokio::time::timeout(Duration::from_secs(10), alarms.recv_async())
        .await
        .expect("the instance's alarm reaches the viewer")
        .unwrap();
    let source = Source::decode(&real.attachment().unwrap().to_bytes()).unwrap();
    assert_eq!(source.instance, "secure-a");
    let json = real.payload().to_bytes().into_owned();
    let Record::Alarm(alarm) = glrmon_wire::decode_record(&json).unwrap() else {
        panic!("not an alarm");
    };
    assert!((200..300).contains(&alarm.k), "{alarm:?}");

    // Forgeries: the same record again from the plant publisher and from the viewer,
    // and an alarm of a channel that does not exist, with a source attached.
    let ghost = String::from_utf8(json.clone())
        .unwrap()
        .replace("\"dc_motor\"", "\"ghost\"");
    // (A session's own puts reach its own subscribers without the router: the viewer
    // forges from a session of its own.)
    let forger = zenoh::open(open(&viewer_cfg)).await.unwrap();
    for (who, session) in [("plant", &plant), ("viewer", &forger)] {
        session
            .put("glrmon/dc_motor/alarm", json.clone())
            .attachment(
                Source {
                    instance: format!("secure-a (forged by {who})"),
                    generation: 0,
                }
                .encode(),
            )
            .await
            .unwrap();
        session
            .put("glrmon/ghost/alarm", ghost.clone())
            .await
            .unwrap();
    }
    let forged = tokio::time::timeout(Duration::from_secs(2), alarms.recv_async()).await;
    assert!(
        forged.is_err(),
        "a forged alarm went through: {:?}",
        forged.map(|s| s.map(|s| (
            s.key_expr().to_string(),
            String::from_utf8_lossy(&s.payload().to_bytes()).into_owned(),
            s.attachment()
                .map(|a| String::from_utf8_lossy(&a.to_bytes()).into_owned())
        )))
    );

    // The control: the same put from a session with the instances' certificate passes,
    // so the router refused the others for their role, not for the route.
    let insider = zenoh::open(open(&glrmon_cfg)).await.unwrap();
    insider
        .put("glrmon/dc_motor/alarm", json.clone())
        .attachment(
            Source {
                instance: "control".to_owned(),
                generation: 0,
            }
            .encode(),
        )
        .await
        .unwrap();
    let control = tokio::time::timeout(Duration::from_secs(5), alarms.recv_async())
        .await
        .expect("the put of a glrmon certificate passes")
        .unwrap();
    assert_eq!(
        Source::decode(&control.attachment().unwrap().to_bytes())
            .unwrap()
            .instance,
        "control"
    );
    insider.close().await.unwrap();

    // A client whose certificate another authority signed cannot open a session.
    // (It trusts the router's authority, so only the router's check can refuse it.)
    let stranger = Authority::new("another CA");
    let stranger_dir = dir.join("stranger");
    std::fs::create_dir_all(&stranger_dir).unwrap();
    let stranger_cfg = client_config(&stranger, &ca, "glrmon", &stranger_dir, port);
    let opened = tokio::time::timeout(Duration::from_secs(20), zenoh::open(open(&stranger_cfg)))
        .await
        .expect("opening gives up");
    assert!(
        opened.is_err(),
        "a client of another authority opened a session"
    );

    // `glrmon status` through the viewer's configuration.
    let out = support::run_ok(
        support::glrmon()
            .args(["status", "--zenoh-config"])
            .arg(&viewer_cfg),
    );
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("secure-a"), "{table}");

    drop((alarms, publisher));
    viewer.close().await.unwrap();
    forger.close().await.unwrap();
    plant.close().await.unwrap();
    router.stop().await;
}
