//! Encodings of a match's answers that its readers share: each is made at most once per
//! tick however many ask for it (the first reader makes it while the others wait for the
//! same cell), and is dropped when the match moves on.
//!
//! The bytes are opaque here (the wire shapes live in `protocol`); a key says what was
//! encoded and for whom (`GET …/belief`: the robot, the reader's sight, the thinning).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use tokio::sync::OnceCell;

/// One encoding, and its gzip'd form once a reader that takes gzip asked for it (`Bytes`:
/// every response shares them without a copy).
#[derive(Debug, Default)]
pub struct Encoded {
    pub bytes: bytes::Bytes,
    pub gzip: OnceCell<bytes::Bytes>,
}

/// The cell readers of one tick share.
type Cell = Arc<OnceCell<Arc<Encoded>>>;

/// A match's shared encodings, by key: the tick each is of, and its cell.
#[derive(Debug, Default)]
pub struct EncodedCache {
    entries: Mutex<HashMap<String, (u64, Cell)>>,
}

/// Keys a match keeps at most: every robot's belief and the team's, for both sights, at a
/// few thinnings. Past it the cache starts again (the next readers encode once more).
const MAX_KEYS: usize = 64;

impl EncodedCache {
    /// The cell of `key` at `tick`: the one readers of that tick share, made empty when the
    /// key was of another tick.
    pub fn cell(&self, key: &str, tick: u64) -> Arc<OnceCell<Arc<Encoded>>> {
        let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((at, cell)) = entries.get(key)
            && *at == tick
        {
            return cell.clone();
        }
        if entries.len() >= MAX_KEYS && !entries.contains_key(key) {
            entries.clear();
        }
        let cell = Arc::new(OnceCell::new());
        entries.insert(key.to_string(), (tick, cell.clone()));
        cell
    }

    /// Whether `key` at `tick` is encoded already.
    pub fn has(&self, key: &str, tick: u64) -> bool {
        let entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        entries
            .get(key)
            .is_some_and(|(at, cell)| *at == tick && cell.initialized())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn readers_of_one_tick_share_one_encoding() {
        let cache = EncodedCache::default();
        let made = std::sync::atomic::AtomicUsize::new(0);
        let encode = || async {
            made.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            Ok::<_, ()>(Arc::new(Encoded {
                bytes: bytes::Bytes::from_static(b"belief"),
                gzip: OnceCell::new(),
            }))
        };
        for _ in 0..5 {
            let cell = cache.cell("team", 7);
            cell.get_or_try_init(encode).await.unwrap();
        }
        assert_eq!(made.load(std::sync::atomic::Ordering::Relaxed), 1);
        assert!(cache.has("team", 7));
        assert!(!cache.has("team", 8));
        cache.cell("team", 8).get_or_try_init(encode).await.unwrap();
        assert_eq!(made.load(std::sync::atomic::Ordering::Relaxed), 2);
    }
}
