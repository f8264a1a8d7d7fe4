//! The engine's view of the other processes (`ShardPeers`) on top of the timely worker
//! thread: partials the engine sends wait in a queue until the worker thread hands them to
//! timely; partials timely delivers wait, by node key, until the engine asks for them.

use relume_core::shard::{ShardMessage, ShardPayload, ShardPeers};
use relume_core::{CancelToken, Hash, NodeError};
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::AtomicBool;
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// Shared between the engine's threads and the timely worker thread.
pub(crate) struct Bridge {
    process: usize,
    processes: usize,
    shared_cache: bool,
    /// Encoded messages to send to every other process.
    outgoing: Mutex<VecDeque<Vec<u8>>>,
    /// Messages received, by node key.
    incoming: Mutex<HashMap<Hash, VecDeque<ShardMessage>>>,
    arrived: Condvar,
    /// Set when the engine's run is over: the worker thread sends what is queued and stops.
    pub done: AtomicBool,
    /// Why the connection to the peers broke (a timely thread panicked), once it has.
    broken: Mutex<Option<String>>,
}

impl Bridge {
    pub fn new(process: usize, processes: usize, shared_cache: bool) -> Bridge {
        Bridge {
            process,
            processes,
            shared_cache,
            outgoing: Mutex::default(),
            incoming: Mutex::default(),
            arrived: Condvar::new(),
            done: AtomicBool::new(false),
            broken: Mutex::new(None),
        }
    }

    /// The messages waiting to be sent (taken).
    pub fn take_outgoing(&self) -> Vec<Vec<u8>> {
        self.outgoing.lock().unwrap().drain(..).collect()
    }

    /// A message timely delivered; undecodable bytes (another build of relume) break the run.
    pub fn deliver(&self, bytes: &[u8]) {
        match decode(bytes) {
            Some(m) => {
                self.incoming.lock().unwrap().entry(m.node_key).or_default().push_back(m);
                self.arrived.notify_all();
            }
            None => self.set_broken("a peer sent a message this build cannot read: run the same relume build on every machine".into()),
        }
    }

    /// Marks the connection as broken, waking every waiting receiver.
    pub fn set_broken(&self, why: String) {
        self.broken.lock().unwrap().get_or_insert(why);
        let _guard = self.incoming.lock().unwrap();
        self.arrived.notify_all();
    }

    pub fn broken(&self) -> Option<String> {
        self.broken.lock().unwrap().clone()
    }
}

impl ShardPeers for Bridge {
    fn process(&self) -> usize {
        self.process
    }
    fn processes(&self) -> usize {
        self.processes
    }
    fn shared_cache(&self) -> bool {
        self.shared_cache
    }
    fn send(&self, msg: ShardMessage) -> Result<(), NodeError> {
        if let Some(why) = self.broken() {
            return Err(NodeError::failed(format!("lost the other processes: {why}")));
        }
        self.outgoing.lock().unwrap().push_back(encode(&msg));
        Ok(())
    }
    fn recv(&self, node_key: &Hash, cancel: &CancelToken) -> Result<ShardMessage, NodeError> {
        let mut incoming = self.incoming.lock().unwrap();
        loop {
            if let Some(m) = incoming.get_mut(node_key).and_then(VecDeque::pop_front) {
                return Ok(m);
            }
            if cancel.is_cancelled() {
                return Err(NodeError::Cancelled);
            }
            if let Some(why) = self.broken() {
                return Err(NodeError::failed(format!("lost the other processes while waiting for their results: {why}")));
            }
            incoming = self.arrived.wait_timeout(incoming, Duration::from_millis(100)).unwrap().0;
        }
    }
}

/// Wire form: node key (32 bytes), chunk, sender (u64 LE), cached (1 byte), ms (f64 LE), then
/// a tag byte: 0 and a 32-byte cache key, or 1 and the partial's encoding.
pub(crate) fn encode(m: &ShardMessage) -> Vec<u8> {
    let mut b = Vec::with_capacity(90);
    b.extend_from_slice(&m.node_key.0);
    b.extend_from_slice(&m.chunk.to_le_bytes());
    b.extend_from_slice(&(m.from as u64).to_le_bytes());
    b.push(m.cached as u8);
    b.extend_from_slice(&m.ms.to_le_bytes());
    match &m.payload {
        ShardPayload::Key(k) => {
            b.push(0);
            b.extend_from_slice(&k.0);
        }
        ShardPayload::Bytes(p) => {
            b.push(1);
            b.extend_from_slice(p);
        }
    }
    b
}

/// The inverse of `encode`; `None` for bytes it did not write.
pub(crate) fn decode(b: &[u8]) -> Option<ShardMessage> {
    let hash = |s: &[u8]| -> Option<Hash> { Some(Hash(s.try_into().ok()?)) };
    let u64_at = |at: usize| -> Option<u64> { Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?)) };
    let node_key = hash(b.get(0..32)?)?;
    let (chunk, from) = (u64_at(32)?, usize::try_from(u64_at(40)?).ok()?);
    let cached = match *b.get(48)? {
        0 => false,
        1 => true,
        _ => return None,
    };
    let ms = f64::from_bits(u64_at(49)?);
    let payload = match *b.get(57)? {
        0 if b.len() == 58 + 32 => ShardPayload::Key(hash(&b[58..])?),
        1 => ShardPayload::Bytes(b[58..].to_vec()),
        _ => return None,
    };
    Some(ShardMessage { node_key, chunk, from, cached, ms, payload })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(payload: ShardPayload) -> ShardMessage {
        ShardMessage { node_key: Hash::of_bytes(b"node"), chunk: 7, from: 2, cached: true, ms: 12.5, payload }
    }

    #[test]
    fn messages_round_trip_and_bad_bytes_are_refused() {
        for m in [msg(ShardPayload::Key(Hash::of_bytes(b"k"))), msg(ShardPayload::Bytes(vec![1, 2, 3]))] {
            let b = encode(&m);
            let back = decode(&b).unwrap();
            assert_eq!((back.node_key, back.chunk, back.from, back.cached, back.ms), (m.node_key, 7, 2, true, 12.5));
            assert_eq!(format!("{:?}", back.payload), format!("{:?}", m.payload));
            for cut in 0..58 {
                assert!(decode(&b[..cut]).is_none(), "cut at {cut}");
            }
        }
        let mut b = encode(&msg(ShardPayload::Key(Hash::default())));
        b.push(0);
        assert!(decode(&b).is_none(), "a key payload of the wrong length");
    }

    #[test]
    fn receivers_get_their_node_s_messages_in_order_and_wake_when_the_peers_are_lost() {
        let bridge = Bridge::new(0, 2, false);
        let other = ShardMessage { node_key: Hash::of_bytes(b"other"), ..msg(ShardPayload::Bytes(vec![9])) };
        bridge.deliver(&encode(&other));
        bridge.deliver(&encode(&ShardMessage { chunk: 1, ..msg(ShardPayload::Bytes(vec![])) }));
        bridge.deliver(&encode(&ShardMessage { chunk: 2, ..msg(ShardPayload::Bytes(vec![])) }));
        let cancel = CancelToken::new();
        let key = Hash::of_bytes(b"node");
        assert_eq!(bridge.recv(&key, &cancel).unwrap().chunk, 1);
        assert_eq!(bridge.recv(&key, &cancel).unwrap().chunk, 2);
        std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(Duration::from_millis(50));
                bridge.set_broken("process 1 stopped".into());
            });
            let e = bridge.recv(&key, &cancel).unwrap_err();
            assert!(e.to_string().contains("process 1 stopped"), "{e}");
        });
        assert!(bridge.send(msg(ShardPayload::Bytes(vec![]))).is_err(), "nothing is sent once the peers are lost");
    }
}
