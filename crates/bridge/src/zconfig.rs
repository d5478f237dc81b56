//! The bridge's Zenoh configuration: safe on a network by default.

use robobus::ops::OpError;

use crate::{BridgeConfig, BridgeError, ZenohMode, zerr};

/// Where a bridge listens unless told otherwise: loopback only.
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7447";
/// The longest namespace, characters.
const MAX_NAMESPACE: usize = 128;
/// The most endpoints of each kind.
const MAX_ENDPOINTS: usize = 16;

/// The key prefix of `namespace` (`bot1` gives `bot1/`; `None` gives none). A leading or
/// trailing `/` is dropped (`/bot1` as ROS 2 writes it); the rest must be chunks of
/// letters, digits, `_` and `-` separated by single `/` (no Zenoh wildcards or
/// specials), at most 128 characters.
pub fn namespace_prefix(namespace: Option<&str>) -> Result<String, OpError> {
    let Some(ns) = namespace else {
        return Ok(String::new());
    };
    let ns = ns.trim_matches('/');
    let bad = |why: &str| {
        OpError::invalid(
            "--namespace",
            format!("\"{}\"", ns.chars().take(MAX_NAMESPACE).collect::<String>()),
            why.to_owned(),
        )
    };
    if ns.is_empty() {
        return Ok(String::new());
    }
    if ns.chars().count() > MAX_NAMESPACE {
        return Err(bad("at most 128 characters"));
    }
    let chunk_ok = |c: &str| {
        !c.is_empty()
            && c.chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-')
    };
    if !ns.split('/').all(chunk_ok) {
        return Err(bad(
            "chunks of letters, digits, '_' and '-' separated by single '/' (like bot1 or \
             site/arm)",
        ));
    }
    Ok(format!("{ns}/"))
}

fn endpoints(option: &str, list: &[String]) -> Result<String, OpError> {
    if list.len() > MAX_ENDPOINTS {
        return Err(OpError::invalid(
            option,
            format!("{} endpoints", list.len()),
            format!("at most {MAX_ENDPOINTS}"),
        ));
    }
    for e in list {
        let ok = e.len() <= 256
            && e.split_once('/')
                .is_some_and(|(proto, addr)| !proto.is_empty() && !addr.is_empty())
            && !e.contains(['"', '\\', '\n']);
        if !ok {
            return Err(OpError::invalid(
                option,
                e,
                "a Zenoh endpoint PROTOCOL/ADDRESS:PORT, like tcp/127.0.0.1:7447",
            ));
        }
    }
    serde_json::to_string(list).map_err(|e| OpError::invalid(option, "endpoints", e.to_string()))
}

/// The Zenoh configuration of a bridge: the file's if one is given (TLS, access
/// control, credentials), then the mode (peer or client), exactly the listen and connect endpoints
/// asked for, and multicast and gossip scouting off (peers meet through the endpoints).
pub(crate) fn build(config: &BridgeConfig) -> Result<zenoh::Config, BridgeError> {
    let mut z = match &config.zenoh_config {
        Some(path) => zenoh::Config::from_file(path).map_err(|e| {
            OpError::invalid(
                "--zenoh-config",
                path.display(),
                format!("a Zenoh configuration file (JSON5 or YAML): {e}"),
            )
        })?,
        None => zenoh::Config::default(),
    };
    let listen = endpoints("--listen", &config.listen)?;
    let connect = endpoints("--connect", &config.connect)?;
    if config.mode == ZenohMode::Client {
        if config.connect.is_empty() {
            return Err(OpError::invalid(
                "--connect",
                "no endpoint",
                "at least one router to connect to in client mode (--mode client)",
            )
            .into());
        }
        if let Some(first) = config.listen.first() {
            return Err(OpError::invalid(
                "--listen",
                first,
                "no endpoint in client mode (--mode client): a client only connects",
            )
            .into());
        }
    }
    for (key, value) in [
        ("mode", format!("\"{}\"", config.mode.name())),
        ("listen/endpoints", listen),
        ("connect/endpoints", connect),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "false".to_owned()),
    ] {
        z.insert_json5(key, &value).map_err(zerr)?;
    }
    Ok(z)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn namespaces_are_key_chunks() {
        assert_eq!(namespace_prefix(None).unwrap(), "");
        assert_eq!(namespace_prefix(Some("/bot1")).unwrap(), "bot1/");
        assert_eq!(
            namespace_prefix(Some("site/arm_2/")).unwrap(),
            "site/arm_2/"
        );
        for bad in ["a//b", "a/*", "a/**", "x$y", "a b", "é"] {
            let e = namespace_prefix(Some(bad)).unwrap_err();
            assert_eq!(e.kind(), robobus::ErrorKind::BadInput, "{bad}");
            assert!(e.to_string().contains("--namespace"), "{e}");
        }
        assert!(namespace_prefix(Some(&"a".repeat(129))).is_err());
    }

    #[test]
    fn the_default_listens_on_loopback_with_scouting_off() {
        let z = build(&BridgeConfig::default()).unwrap();
        assert_eq!(
            z.get_json("listen/endpoints").unwrap(),
            r#"["tcp/127.0.0.1:7447"]"#
        );
        assert_eq!(z.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(z.get_json("scouting/gossip/enabled").unwrap(), "false");
        assert_eq!(z.get_json("mode").unwrap(), r#""peer""#);
    }

    #[test]
    fn a_client_connects_and_listens_on_nothing() {
        let client = |listen: Vec<String>, connect: Vec<String>| {
            build(&BridgeConfig {
                mode: ZenohMode::Client,
                listen,
                connect,
                ..BridgeConfig::default()
            })
        };
        let z = client(vec![], vec!["tcp/10.0.0.1:7447".into()]).unwrap();
        assert_eq!(z.get_json("mode").unwrap(), r#""client""#);
        assert_eq!(z.get_json("listen/endpoints").unwrap(), "[]");
        let e = client(vec![], vec![]).unwrap_err();
        assert!(e.to_string().contains("--connect"), "{e}");
        assert_eq!(e.kind(), robobus::ErrorKind::BadInput);
        let e = client(
            vec![DEFAULT_LISTEN.to_owned()],
            vec!["tcp/10.0.0.1:7447".into()],
        )
        .unwrap_err();
        assert!(e.to_string().contains("--listen"), "{e}");
    }

    #[test]
    fn bad_endpoints_name_the_option() {
        let e = build(&BridgeConfig {
            connect: vec!["127.0.0.1:7447".into()],
            ..BridgeConfig::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("--connect"), "{e}");
        assert_eq!(e.kind(), robobus::ErrorKind::BadInput);
    }
}
