//! The run's own observers (the default EKF and the reference filter) stepped on a thread of
//! their own, pipelined with the closed loop.
//!
//! Nothing in the closed loop depends on them: the loop hands their inputs (the voltage
//! `u[k-1]`, the measured currents `i[k]`, and the true angle and speed to score against)
//! over in batches of [`BATCH`] periods, and gets their scored estimates back in the same
//! batches and order. The loop keeps each period's [`Sample`] until its estimates are back,
//! fills them in, and only then hands the sample on (metrics, sinks, trace): everything
//! downstream sees the samples in order and complete, exactly as in a sequential run. The
//! observers step in the same order on the same inputs, so their results are the same bit for
//! bit; [`ObserverPipeline::inline`] steps them on the caller's thread at each hand-over (the
//! sequential reference, and the fall-back when no thread can be spawned).
//!
//! A panic of the worker is re-raised on the caller's thread when its results go missing (a
//! panic of the sequential loop would have ended the run the same way); it can neither hang
//! the run nor be lost.

use std::collections::VecDeque;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use ekf_core::{EkfError, PmsmObserver};

use crate::drive::rotor_observers::Observer;
use crate::output::record::{ObserverSample, Sample, Truth};

/// Periods per batch handed to the worker. The loop keeps the samples of up to
/// `IN_FLIGHT + 1` batches (about 1.2 KB each) until their estimates are back: small enough
/// to stay in the L2 cache (with 256 x 5 they did not, and the merge paid for the misses),
/// large enough that the worker's wake-ups (one a batch when it has caught up) cost little.
pub(crate) const BATCH: usize = 128;
/// Batches on their way (sent, estimates not yet merged) before the loop waits for the first.
const IN_FLIGHT: usize = 2;

/// The observers' inputs of one period.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ObserverInput {
    /// Period index.
    pub k: u64,
    /// Voltage over the previous period as the controller knows it.
    pub u_prev: [f64; 2],
    /// Measured currents.
    pub i_ab_a: [f64; 2],
    /// True electrical angle, rad (scoring).
    pub theta_e_rad: f64,
    /// True electrical speed, rad/s (scoring).
    pub omega_e_rad_s: f64,
}

/// The observers' scored estimates of one period.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ObserverOutput {
    /// The default EKF (its error ends the run).
    pub observer: Result<ObserverSample, EkfError>,
    /// The reference filter: `None` when it is off or was dropped; its error drops it.
    pub reference_filter: Option<Result<ObserverSample, EkfError>>,
}

/// The run's own observers.
pub(crate) struct RunObservers {
    /// The default EKF.
    pub observer: PmsmObserver<f64>,
    /// The reference filter, while it runs.
    pub reference_filter: Option<PmsmObserver<f64>>,
}

impl RunObservers {
    /// Steps the observers on `inputs`, appending to `out`, up to and including the first
    /// failure of the default EKF (after it nothing steps: the run ends there).
    fn step_batch(&mut self, inputs: &[ObserverInput], out: &mut Vec<ObserverOutput>) -> bool {
        for x in inputs {
            let truth_at = |e: &crate::drive::rotor_observers::ObserverEstimate| {
                ObserverSample::from_controller(
                    e,
                    &Truth {
                        theta_e_rad: x.theta_e_rad,
                        omega_e_rad_s: x.omega_e_rad_s,
                        ..Truth::default()
                    },
                )
            };
            let observer = match Observer::step(&mut self.observer, x.u_prev, x.i_ab_a) {
                Ok(e) => truth_at(&e),
                Err(error) => {
                    out.push(ObserverOutput {
                        observer: Err(error),
                        reference_filter: None,
                    });
                    return false;
                }
            };
            let reference_filter = match self
                .reference_filter
                .as_mut()
                .map(|f| Observer::step(f, x.u_prev, x.i_ab_a))
            {
                Some(Ok(e)) => Some(Ok(truth_at(&e))),
                Some(Err(error)) => {
                    self.reference_filter = None;
                    Some(Err(error))
                }
                None => None,
            };
            out.push(ObserverOutput {
                observer: Ok(observer),
                reference_filter,
            });
        }
        true
    }
}

/// One batch: the inputs and, once stepped, the outputs (the vectors go back and forth).
struct Job {
    inputs: Vec<ObserverInput>,
    outputs: Vec<ObserverOutput>,
}

/// Where the observers step.
enum Worker {
    /// On the caller's thread, at each hand-over (the stepped batches wait in the queue).
    Inline(Box<RunObservers>, VecDeque<Job>),
    /// On a thread of their own.
    Thread {
        jobs: Option<Sender<Job>>,
        results: Receiver<Job>,
        handle: Option<JoinHandle<()>>,
    },
}

/// What [`ObserverPipeline`] hands on, period by period in order.
pub(crate) enum Ready<'a> {
    /// A period whose observers stepped.
    Period {
        /// The completed sample (`None` for a period whose controller output ended the
        /// run: only its observers' steps count).
        sample: Option<&'a Sample>,
        /// The observers' inputs of the period.
        input: &'a ObserverInput,
        /// The reference filter failed in this period (and was dropped).
        reference_filter_error: Option<EkfError>,
    },
    /// The default EKF failed in period `k`: the run ends there (nothing after it is handed
    /// on).
    ObserverFailed {
        /// Period index.
        k: u64,
        /// The error.
        error: EkfError,
    },
}

/// The pipeline (module docs).
pub(crate) struct ObserverPipeline {
    worker: Worker,
    /// The batch being filled: its inputs and its samples (awaiting their estimates).
    inputs: Vec<ObserverInput>,
    samples: Vec<Option<Sample>>,
    /// Samples of the batches sent, oldest first.
    waiting: VecDeque<Vec<Option<Sample>>>,
    spare_jobs: Vec<Job>,
    spare_samples: Vec<Vec<Option<Sample>>>,
    /// The default EKF failed: nothing after its failure is handed on.
    stopped: bool,
}

impl ObserverPipeline {
    /// Observers stepped on the caller's thread.
    pub fn inline(observers: RunObservers) -> Self {
        Self::with(Worker::Inline(Box::new(observers), VecDeque::new()))
    }

    /// Observers stepped on a thread of their own (inline when no thread can be spawned).
    pub fn threaded(observers: RunObservers) -> Self {
        let (jobs, queue) = channel::<Job>();
        let (done, results) = channel::<Job>();
        // The observers go to the thread through this slot: should the spawn fail, they are
        // taken back and step inline.
        let slot = Arc::new(Mutex::new(Some(observers)));
        let theirs = Arc::clone(&slot);
        let spawned = std::thread::Builder::new()
            .name("pmsm-sim observers".into())
            .spawn(move || {
                let Some(mut obs) = theirs.lock().ok().and_then(|mut s| s.take()) else {
                    return;
                };
                for mut job in queue {
                    job.outputs.clear();
                    let go_on = obs.step_batch(&job.inputs, &mut job.outputs);
                    if done.send(job).is_err() || !go_on {
                        return;
                    }
                }
            });
        match spawned {
            Ok(handle) => Self::with(Worker::Thread {
                jobs: Some(jobs),
                results,
                handle: Some(handle),
            }),
            Err(_) => {
                let obs = slot.lock().ok().and_then(|mut s| s.take());
                match obs {
                    Some(obs) => Self::inline(obs),
                    // Unreachable: a thread that was never spawned took nothing.
                    None => panic!("observer thread failed to spawn and its observers are lost"),
                }
            }
        }
    }

    fn with(worker: Worker) -> Self {
        Self {
            worker,
            inputs: Vec::with_capacity(BATCH),
            samples: Vec::with_capacity(BATCH),
            waiting: VecDeque::with_capacity(IN_FLIGHT + 1),
            spare_jobs: Vec::new(),
            spare_samples: Vec::new(),
            stopped: false,
        }
    }

    /// Adds a period: its observers' inputs and its sample (without the observers'
    /// estimates). When a batch is full, hands it over, and hands on (`f`, in order) the
    /// periods whose estimates are back; `f` returning `false` stops the hand-on (the run
    /// ends there). Returns `false` once the run is to end.
    #[inline]
    pub fn push(
        &mut self,
        input: ObserverInput,
        sample: Option<Sample>,
        f: &mut dyn FnMut(Ready<'_>) -> bool,
    ) -> bool {
        self.inputs.push(input);
        self.samples.push(sample);
        if self.inputs.len() < BATCH {
            return true;
        }
        self.batch_full(f)
    }

    /// The current batch is full: hands it over, merges what is back.
    #[inline(never)]
    fn batch_full(&mut self, f: &mut dyn FnMut(Ready<'_>) -> bool) -> bool {
        self.send();
        // Merge what is back; wait only when too many batches are on their way.
        while !self.stopped && !self.waiting.is_empty() {
            let wait = self.waiting.len() > IN_FLIGHT;
            match self.receive(wait) {
                Some(job) => self.hand_on(job, f),
                None => break,
            }
        }
        !self.stopped
    }

    /// Hands over what is left and hands on every period still waiting.
    pub fn finish(&mut self, f: &mut dyn FnMut(Ready<'_>) -> bool) {
        if !self.inputs.is_empty() {
            self.send();
        }
        while !self.stopped && !self.waiting.is_empty() {
            match self.receive(true) {
                Some(job) => self.hand_on(job, f),
                None => break,
            }
        }
        self.shut_down();
    }

    /// Sends the current batch.
    fn send(&mut self) {
        let mut job = self.spare_jobs.pop().unwrap_or_else(|| Job {
            inputs: Vec::with_capacity(BATCH),
            outputs: Vec::with_capacity(BATCH),
        });
        std::mem::swap(&mut job.inputs, &mut self.inputs);
        self.inputs.clear();
        let fresh = self
            .spare_samples
            .pop()
            .unwrap_or_else(|| Vec::with_capacity(BATCH));
        self.waiting
            .push_back(std::mem::replace(&mut self.samples, fresh));
        match &mut self.worker {
            Worker::Inline(obs, done) => {
                job.outputs.clear();
                obs.step_batch(&job.inputs, &mut job.outputs);
                done.push_back(job);
            }
            Worker::Thread { jobs, .. } => {
                // A closed queue means the worker has ended: `receive` finds out why.
                if let Some(tx) = jobs.as_ref() {
                    let _ = tx.send(job);
                }
            }
        }
    }

    /// The oldest batch's stepped job, if it is back (`wait`: waits for it). Re-raises the
    /// worker's panic if it ended without answering.
    fn receive(&mut self, wait: bool) -> Option<Job> {
        match &mut self.worker {
            Worker::Inline(_, done) => done.pop_front(),
            Worker::Thread {
                results, handle, ..
            } => {
                let got = if wait {
                    results.recv().ok()
                } else {
                    match results.try_recv() {
                        Ok(job) => Some(job),
                        Err(std::sync::mpsc::TryRecvError::Empty) => return None,
                        Err(std::sync::mpsc::TryRecvError::Disconnected) => None,
                    }
                };
                if got.is_none() {
                    // The worker is gone without this batch: it panicked (it only ends early
                    // after sending the batch with the failure, which `hand_on` stops at).
                    if let Some(h) = handle.take()
                        && let Err(panic) = h.join()
                    {
                        std::panic::resume_unwind(panic);
                    }
                    self.stopped = true;
                }
                got
            }
        }
    }

    /// Merges a stepped batch into its samples and hands them on.
    fn hand_on(&mut self, job: Job, f: &mut dyn FnMut(Ready<'_>) -> bool) {
        let Some(mut samples) = self.waiting.pop_front() else {
            return;
        };
        for ((slot, out), input) in samples.iter_mut().zip(&job.outputs).zip(&job.inputs) {
            let observer = match out.observer {
                Ok(o) => o,
                Err(error) => {
                    f(Ready::ObserverFailed { k: input.k, error });
                    self.stopped = true;
                    break;
                }
            };
            let (seed, reference_filter_error) = match out.reference_filter {
                Some(Ok(o)) => (Some(o), None),
                Some(Err(e)) => (None, Some(e)),
                None => (None, None),
            };
            let sample = slot.as_mut().map(|s| {
                s.observer = observer;
                s.seed_filter = seed;
                &*s
            });
            if !f(Ready::Period {
                sample,
                input,
                reference_filter_error,
            }) {
                self.stopped = true;
                break;
            }
        }
        samples.clear();
        self.spare_samples.push(samples);
        self.spare_jobs.push(job);
    }

    /// Ends the worker: closes its queue, lets it finish, joins it (re-raising its panic).
    fn shut_down(&mut self) {
        if let Worker::Thread {
            jobs,
            results,
            handle,
        } = &mut self.worker
        {
            jobs.take();
            // Let the worker finish what it has (it stops at the closed queue).
            while results.recv().is_ok() {}
            if let Some(h) = handle.take()
                && let Err(panic) = h.join()
            {
                std::panic::resume_unwind(panic);
            }
        }
    }
}

impl Drop for ObserverPipeline {
    fn drop(&mut self) {
        if let Worker::Thread { jobs, handle, .. } = &mut self.worker {
            jobs.take();
            if let Some(h) = handle.take() {
                let _ = h.join();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    fn observers() -> RunObservers {
        let sc = Scenario::preset("default").unwrap_or_else(|e| panic!("{e}"));
        let new = |c| PmsmObserver::new(&c).unwrap_or_else(|e| panic!("{e:?}"));
        RunObservers {
            observer: new(sc.observer_config()),
            reference_filter: Some(new(sc.reference_filter_config())),
        }
    }

    /// Pushes `n` periods (a NaN voltage at `bad`: the default EKF fails there) and records
    /// what is handed on.
    fn drive(mut p: ObserverPipeline, n: u64, bad: Option<u64>) -> Vec<String> {
        let mut seen = Vec::new();
        let mut f = |r: Ready<'_>| -> bool {
            match r {
                Ready::Period {
                    sample,
                    input,
                    reference_filter_error,
                } => seen.push(format!(
                    "{} {:?} {:?}",
                    input.k,
                    sample.map(|s| (s.k, s.observer, s.seed_filter)),
                    reference_filter_error
                )),
                Ready::ObserverFailed { k, error } => seen.push(format!("failed {k} {error:?}")),
            }
            true
        };
        for k in 0..n {
            let u = if Some(k) == bad { f64::NAN } else { 1.0 };
            let input = ObserverInput {
                k,
                u_prev: [u, -0.5 * u],
                i_ab_a: [0.01 * (k as f64).sin(), 0.01 * (k as f64).cos()],
                theta_e_rad: 0.0,
                omega_e_rad_s: 0.0,
            };
            let sample = Sample {
                k,
                ..Sample::default()
            };
            if !p.push(input, Some(sample), &mut f) {
                break;
            }
        }
        p.finish(&mut f);
        seen
    }

    #[test]
    fn threaded_and_inline_hand_on_the_same_periods_in_order() {
        let a = drive(ObserverPipeline::threaded(observers()), 1000, None);
        let b = drive(ObserverPipeline::inline(observers()), 1000, None);
        assert_eq!(a.len(), 1000);
        assert_eq!(a, b);
        assert!(a[999].starts_with("999 Some((999, "));
    }

    #[test]
    fn an_observer_failure_ends_the_hand_on_at_its_period() {
        for bad in [0, 200, 255, 256, 999] {
            let a = drive(ObserverPipeline::threaded(observers()), 1000, Some(bad));
            let b = drive(ObserverPipeline::inline(observers()), 1000, Some(bad));
            assert_eq!(a, b, "bad {bad}");
            // Every period before it, then the failure, nothing after.
            assert_eq!(a.len() as u64, bad + 1, "bad {bad}");
            assert_eq!(a[bad as usize], format!("failed {bad} NonFiniteInput"));
        }
    }
}
