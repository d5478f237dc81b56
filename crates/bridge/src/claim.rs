//! One bridge per namespace: a bridge refuses a namespace another bridge serves.
//!
//! Before it declares any key, a bridge asks Zenoh for the liveliness tokens of its
//! namespace: the documented `NS/robobus/bridge`, and the claims `NS/robobus/bridge/C`
//! bridges declare next to it (`C`: the bridge's start time, in nanoseconds since the Unix
//! epoch, zero-padded, then `-` and its Zenoh ID). If one is up, the bridge does not start
//! ([`BridgeError::InUse`]). Otherwise it declares its own claim, asks again, and watches
//! the claims for as long as it runs: of two bridges that started at once (each asked
//! before the other's token was up), the one whose claim orders later (started later, or
//! by Zenoh ID at the same nanosecond) gives way; at start it does not start, later it
//! stops as at its end (everything it moved brought to the safe state).
//!
//! What this guarantees: two bridges whose Zenoh sessions reach each other never both
//! keep serving one namespace; the later one stops as soon as its session sees the
//! earlier one's claim. Bridges that cannot reach each other (two networks not joined
//! yet) cannot know of each other; when the networks join, the later one stops.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use zenoh::Wait as _;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Subscriber;
use zenoh::sample::SampleKind;

use crate::{BridgeError, Keys, zerr};

/// How long a bridge waits for Zenoh's answer about the namespace's tokens.
pub(crate) const LOOKUP_TIMEOUT: Duration = Duration::from_secs(3);

/// The namespace as a message names it.
pub(crate) fn namespace_name(keys: &Keys) -> String {
    let ns = keys
        .alive
        .strip_suffix("robobus/bridge")
        .unwrap_or_default()
        .trim_end_matches('/');
    if ns.is_empty() {
        "the root namespace (no --namespace)".to_owned()
    } else {
        format!("namespace \"{ns}\"")
    }
}

/// The chunk of a claim: start time, then Zenoh ID (they order as the bridges started).
fn chunk(started_ns: u128, zid: &str) -> String {
    format!("{started_ns:039}-{zid}")
}

/// The claim chunk of `key` if it is a claim of `keys`' namespace (`NS/robobus/bridge/C`,
/// `C` one chunk).
fn claim_of<'k>(keys: &Keys, key: &'k str) -> Option<&'k str> {
    key.strip_prefix(keys.alive.as_str())?
        .strip_prefix('/')
        .filter(|c| !c.is_empty() && !c.contains('/'))
}

/// The Zenoh ID in a claim chunk.
fn zid_of(chunk: &str) -> &str {
    chunk.split_once('-').map_or(chunk, |(_, z)| z)
}

/// The error of a namespace in use; `other`: the other bridge's claim, if known.
fn in_use(keys: &Keys, other: Option<&str>, gave_way: bool) -> BridgeError {
    BridgeError::InUse {
        namespace: namespace_name(keys),
        other: other.map(|c| zid_of(c).to_owned()),
        gave_way,
    }
}

/// The tokens of other bridges on `keys`' namespace now: the documented token's key (an
/// older bridge has only that) or claim chunks, except `own`.
fn others(
    session: &zenoh::Session,
    keys: &Keys,
    own: Option<&str>,
) -> Result<Vec<String>, BridgeError> {
    let replies = session
        .liveliness()
        .get(format!("{}/**", keys.alive))
        .timeout(LOOKUP_TIMEOUT)
        .wait()
        .map_err(zerr)?;
    let mut found = Vec::new();
    while let Ok(reply) = replies.recv() {
        let Ok(sample) = reply.result() else {
            continue;
        };
        let key = sample.key_expr().as_str();
        if let Some(c) = claim_of(keys, key) {
            if Some(c) != own {
                found.push(c.to_owned());
            }
        } else if key == keys.alive && own.is_none() {
            found.push(key.to_owned());
        }
    }
    found.sort();
    found.dedup();
    Ok(found)
}

/// A bridge's claim on its namespace: its token and the watch on the others' (both
/// withdrawn when dropped).
pub(crate) struct Claim {
    _token: LivelinessToken,
    _watch: Subscriber<()>,
}

/// Claims `keys`' namespace on `session`: refused if another bridge holds it (see the
/// [module docs](self)); `give_way` runs (once, on a Zenoh thread) with the error when a
/// bridge that started earlier turns up later.
pub(crate) fn claim(
    session: &zenoh::Session,
    keys: &Keys,
    give_way: impl Fn(BridgeError) + Send + Sync + 'static,
) -> Result<Claim, BridgeError> {
    let found = others(session, keys, None)?;
    if !found.is_empty() {
        // A claim names the other bridge; the documented token alone does not.
        let other = found.iter().find(|c| !c.contains('/'));
        return Err(in_use(keys, other.map(String::as_str), false));
    }
    let started = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let own = chunk(started, &session.zid().to_string());
    let token = session
        .liveliness()
        .declare_token(format!("{}/{own}", keys.alive))
        .wait()
        .map_err(zerr)?;
    let watch_keys = keys.clone();
    let watch_own = own.clone();
    let given = std::sync::atomic::AtomicBool::new(false);
    let watch = session
        .liveliness()
        .declare_subscriber(format!("{}/*", keys.alive))
        .history(true)
        .callback(move |sample| {
            if sample.kind() != SampleKind::Put {
                return;
            }
            if let Some(c) = claim_of(&watch_keys, sample.key_expr().as_str())
                && c < watch_own.as_str()
                && !given.swap(true, std::sync::atomic::Ordering::SeqCst)
            {
                give_way(in_use(&watch_keys, Some(c), true));
            }
        })
        .wait()
        .map_err(zerr)?;
    if let Some(earlier) = others(session, keys, Some(&own))?
        .into_iter()
        .find(|c| *c < own)
    {
        return Err(in_use(keys, Some(&earlier), true));
    }
    Ok(Claim {
        _token: token,
        _watch: watch,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn claims_order_as_the_bridges_started_and_belong_to_their_namespace() {
        let keys = Keys::new(Some("bot1")).unwrap();
        let early = chunk(9, "ff");
        let late = chunk(10, "00");
        assert!(early < late, "{early} {late}");
        assert_eq!(
            claim_of(&keys, &format!("bot1/robobus/bridge/{late}")),
            Some(late.as_str())
        );
        assert_eq!(zid_of(&late), "00");
        // The documented token, another namespace's keys and tokens are no claims.
        for key in [
            "bot1/robobus/bridge",
            "bot1/robobus/bridge/robobus/bridge",
            "bot1/robobus/bridge/",
            "bot2/robobus/bridge/1-ab",
        ] {
            assert_eq!(claim_of(&keys, key), None, "{key}");
        }
        assert_eq!(namespace_name(&keys), "namespace \"bot1\"");
        assert_eq!(
            namespace_name(&Keys::new(None).unwrap()),
            "the root namespace (no --namespace)"
        );
    }
}
