//! timely-dataflow as the transport between processes: its configuration built in code (one
//! worker thread per process, the processes' addresses from the host file), a dataflow that
//! routes every partial to every other process, a start-up timeout (timely retries a peer that
//! never comes forever), and a panic hook that turns timely's "a peer died" panics into an
//! error the waiting engine sees.

use super::peers::Bridge;
use std::sync::{mpsc, Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::Duration;
use timely::dataflow::operators::{Exchange, Input, Inspect};
use timely::dataflow::InputHandle;

/// The running timely thread.
pub(crate) struct Network {
    thread: JoinHandle<Result<(), String>>,
    bridge: Arc<Bridge>,
}

/// Starts this process's timely worker and waits until every peer is connected, at most
/// `timeout`.
pub(crate) fn start(addresses: Vec<String>, process: usize, bridge: Arc<Bridge>, timeout: Duration) -> Result<Network, String> {
    watch_panics(bridge.clone());
    let n = addresses.len();
    let (ready_tx, ready_rx) = mpsc::channel::<()>();
    let worker_bridge = bridge.clone();
    let thread = std::thread::Builder::new()
        .name("relume-timely".into())
        .spawn(move || {
            let config = timely::Config {
                communication: timely::CommunicationConfig::Cluster { threads: 1, process, addresses, report: false, zerocopy: false },
                worker: timely::WorkerConfig::default(),
            };
            let ready = Mutex::new(ready_tx);
            let guards = timely::execute(config, move |worker| {
                let _ = ready.lock().unwrap().send(());
                worker_loop(worker, &worker_bridge);
            })?;
            guards.join().into_iter().collect::<Result<Vec<()>, String>>().map(|_| ())
        })
        .map_err(|e| format!("cannot start the timely thread: {e}"))?;
    match ready_rx.recv_timeout(timeout) {
        Ok(()) => Ok(Network { thread, bridge }),
        Err(mpsc::RecvTimeoutError::Timeout) => Err(format!(
            "process {process} of {n}: not every peer connected within {} s; start every process of the host file (each with its --process index) \
             or raise --connect-timeout",
            timeout.as_secs()
        )),
        Err(mpsc::RecvTimeoutError::Disconnected) => {
            let why = match thread.join() {
                Ok(Err(e)) => e,
                Ok(Ok(())) => "it stopped before starting its worker".to_string(),
                Err(_) => bridge.broken().unwrap_or_else(|| "the timely thread panicked (is the address already in use?)".into()),
            };
            Err(format!("process {process} of {n}: timely could not start: {why}"))
        }
    }
}

impl Network {
    /// Says the run is over, lets timely deliver what is queued and shut down (every process
    /// waits there for the slowest), at most `timeout`.
    pub fn finish(self, timeout: Duration) -> Result<(), String> {
        self.bridge.done.store(true, std::sync::atomic::Ordering::SeqCst);
        let (tx, rx) = mpsc::channel();
        let thread = self.thread;
        std::thread::spawn(move || {
            let _ = tx.send(thread.join());
        });
        match rx.recv_timeout(timeout) {
            Ok(Ok(Ok(()))) => Ok(()),
            Ok(Ok(Err(e))) => Err(e),
            Ok(Err(_)) => Err(self.bridge.broken().unwrap_or_else(|| "the timely thread panicked".into())),
            Err(_) => Err(format!("the other processes did not finish within {} s", timeout.as_secs())),
        }
    }
}

/// One worker: builds the dataflow (input → exchange by destination → hand to the bridge),
/// then moves queued messages into it until the run is done.
fn worker_loop(worker: &mut timely::worker::Worker, bridge: &Arc<Bridge>) {
    let (me, peers) = (worker.index(), worker.peers());
    let mut input: InputHandle<u64, _> = InputHandle::new();
    let deliver = bridge.clone();
    worker.dataflow::<u64, _, _>(|scope| {
        scope
            .input_from(&mut input)
            .container::<Vec<(u64, Vec<u8>)>>()
            .exchange(|m: &(u64, Vec<u8>)| m.0)
            .inspect(move |m: &(u64, Vec<u8>)| deliver.deliver(&m.1));
    });
    let mut round = 0u64;
    loop {
        let done = bridge.done.load(std::sync::atomic::Ordering::SeqCst);
        let out = bridge.take_outgoing();
        for m in &out {
            for p in (0..peers).filter(|&p| p != me) {
                input.send((p as u64, m.clone()));
            }
        }
        if !out.is_empty() {
            round += 1;
            input.advance_to(round);
        }
        if done {
            break;
        }
        worker.step_or_park(Some(Duration::from_millis(5)));
    }
    // Closing the input; timely steps the dataflow until every process has closed its own.
    drop(input);
}

/// The bridge of the running cluster, for the panic hook.
static WATCHED: OnceLock<Mutex<Option<Arc<Bridge>>>> = OnceLock::new();

/// Installs (once) a panic hook that marks the watched bridge broken with the panic's message
/// and stays quiet about timely's own communication panics (a peer that died): the engine
/// reports them as one error instead.
fn watch_panics(bridge: Arc<Bridge>) {
    let slot = WATCHED.get_or_init(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let msg = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let watched = WATCHED.get().and_then(|w| w.lock().ok().and_then(|b| b.clone()));
            let from_timely = msg.contains("timely communication") || msg.contains("MergeQueue") || msg.contains("poison");
            if let Some(b) = watched {
                // The panics that follow the first (threads joining panicked threads) say nothing new.
                if b.broken().is_some() && std::thread::current().name() != Some("main") {
                    return;
                }
                b.set_broken(if from_timely { format!("a connection to another process broke ({msg}): a process stopped") } else { msg });
                if from_timely {
                    return;
                }
            }
            previous(info);
        }));
        Mutex::new(None)
    });
    *slot.lock().unwrap() = Some(bridge);
}
