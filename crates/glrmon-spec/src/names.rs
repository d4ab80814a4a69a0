//! The names a configuration puts on the Zenoh network: instance names and channel
//! names (key chunks), and endpoints.

/// Longest instance name (`daemon.instance`, `glrmon run --instance`).
pub const MAX_INSTANCE_LEN: usize = 64;

/// Checks an instance name: 1 to [`MAX_INSTANCE_LEN`] characters among `A-Z a-z 0-9 _ . -`,
/// so that it is one plain chunk of the status and liveliness keys
/// (`glrmon/@status/<instance>`, `glrmon/@instances/<instance>`): no `/`, no wildcard, no
/// `@`, nothing a shell or a log would mangle.
///
/// # Errors
/// Why the name is refused, as a sentence that follows the field's path.
///
/// # Examples
///
/// ```
/// assert!(glrmon_spec::validate_instance("plant-a.01").is_ok());
/// assert!(glrmon_spec::validate_instance("a/b/**").is_err());
/// assert!(glrmon_spec::validate_instance("").is_err());
/// ```
pub fn validate_instance(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("is empty: an instance name is 1 to 64 characters of A-Z a-z 0-9 _ . -".into());
    }
    if name.len() > MAX_INSTANCE_LEN {
        return Err(format!(
            "has {} characters: at most {MAX_INSTANCE_LEN}",
            name.len()
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-')))
    {
        return Err(format!(
            "\"{}\" contains {c:?}: an instance name is one key chunk of A-Z a-z 0-9 _ . - \
             (it ends the status and liveliness keys glrmon/@status/<instance>)",
            name.escape_debug()
        ));
    }
    Ok(())
}

/// A channel name must be usable in a Zenoh key expression chunk.
pub(crate) fn validate_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("is empty".into());
    }
    if let Some(c) = name.chars().find(|c| {
        matches!(c, '/' | '*' | '$' | '?' | '#' | '@') || c.is_whitespace() || c.is_control()
    }) {
        return Err(format!(
            "\"{name}\" contains '{c}', which cannot appear in a key expression chunk"
        ));
    }
    Ok(())
}

/// Checks the syntax of a Zenoh endpoint, `PROTOCOL/ADDRESS[?metadata][#config]`: a
/// protocol name, and for the IP transports (tcp, udp, tls, quic, ws) an address with a
/// host and a port. The error says why and shows the likely fix (`127.0.0.1:7447` →
/// `tcp/127.0.0.1:7447`). Zenoh itself checks the rest when the session opens.
///
/// # Errors
/// A message for the user when the endpoint is malformed.
///
/// # Examples
///
/// ```
/// assert!(glrmon_spec::check_endpoint("tcp/127.0.0.1:7447").is_ok());
/// let e = glrmon_spec::check_endpoint("127.0.0.1:7447").unwrap_err();
/// assert!(e.contains("tcp/127.0.0.1:7447"));
/// ```
pub fn check_endpoint(s: &str) -> Result<(), String> {
    let hint = |why: &str| {
        let example = if s.contains('/') {
            "tcp/127.0.0.1:7447".to_owned()
        } else {
            format!("tcp/{s}")
        };
        format!("\"{s}\": {why}: an endpoint is PROTOCOL/ADDRESS, e.g. {example}")
    };
    let Some((protocol, rest)) = s.split_once('/') else {
        return Err(hint("no protocol"));
    };
    if protocol.is_empty()
        || !protocol
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-')
    {
        return Err(hint(&format!("\"{protocol}\" is not a protocol")));
    }
    let address = rest.split(['?', '#']).next().unwrap_or_default();
    if address.is_empty() {
        return Err(hint("no address"));
    }
    if matches!(protocol, "tcp" | "udp" | "tls" | "quic" | "ws") {
        let port_ok = address
            .rsplit_once(':')
            .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok());
        if !port_ok {
            return Err(hint(&format!("\"{address}\" is not HOST:PORT")));
        }
    }
    Ok(())
}
