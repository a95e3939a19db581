//! Timeline semaphores (Vulkan 1.2 core) and hand-off submissions: how a recording made on one
//! thread reaches a queue owned by another.
//!
//! A [`Timeline`] counts completed work: submission `k` signals value `k`, anyone may read the
//! counter without blocking ([`Timeline::value`]), a thread may block on a value
//! ([`Timeline::wait`]) — no device-wide stall, no fence — and a host may wait on the value in
//! its own `vkQueueSubmit` (the raw handle is public for that).
//!
//! A [`Handoff`] is a recorded, ended command buffer that the queue's owner submits when it
//! chooses (e.g. between two of its frames). Its recorder keeps a [`Ticket`] to it and, before
//! it resets or frees the command buffer, learns whether it was submitted (then waits for the
//! timeline) or abandoned (then nothing of it ever ran); a hand-off whose recorder is gone
//! refuses to submit. That shared state is a mutex held across the `vkQueueSubmit`, so no
//! interleaving can submit a freed command buffer.

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

use ash::vk;

use super::context::Context;
use super::error::{map_result, GpuError, GpuResult};

/// A timeline semaphore of the context's device, starting at 0. Cloning shares it.
#[derive(Clone)]
pub struct Timeline {
    inner: Arc<TimelineInner>,
}

struct TimelineInner {
    ctx: Context,
    raw: vk::Semaphore,
    name: String,
}

impl Drop for TimelineInner {
    fn drop(&mut self) {
        // SAFETY: every submission signalling this semaphore keeps a clone of the timeline
        // until it has been waited for (recorders do), so no pending work uses it now.
        unsafe { self.ctx.device().destroy_semaphore(self.raw, None) };
    }
}

impl std::fmt::Debug for Timeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Timeline")
            .field("name", &self.inner.name)
            .finish()
    }
}

impl Timeline {
    /// A new timeline at value 0.
    pub fn new(ctx: &Context, name: &str) -> GpuResult<Timeline> {
        let mut kind = vk::SemaphoreTypeCreateInfo::default()
            .semaphore_type(vk::SemaphoreType::TIMELINE)
            .initial_value(0);
        let info = vk::SemaphoreCreateInfo::default().push_next(&mut kind);
        // SAFETY: valid create info (timeline semaphores are enabled on every context's
        // device, see `required_features`); destroyed in Drop.
        let raw = unsafe { ctx.device().create_semaphore(&info, None) }
            .map_err(|r| map_result("vkCreateSemaphore", r))?;
        ctx.set_name(raw, name);
        Ok(Timeline {
            inner: Arc::new(TimelineInner {
                ctx: ctx.clone(),
                raw,
                name: name.to_string(),
            }),
        })
    }

    /// The raw semaphore, for a host that waits on a value in its own submission
    /// (`VkTimelineSemaphoreSubmitInfo`). The host must not signal it.
    pub fn raw(&self) -> vk::Semaphore {
        self.inner.raw
    }

    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// The counter now (never blocks).
    pub fn value(&self) -> GpuResult<u64> {
        let ctx = &self.inner.ctx;
        // SAFETY: the semaphore is a live timeline semaphore of this device.
        unsafe { ctx.device().get_semaphore_counter_value(self.inner.raw) }
            .map_err(|r| ctx.note_error(map_result("vkGetSemaphoreCounterValue", r)))
    }

    /// Blocks until the counter reaches `value` (`Ok(true)`) or `timeout` passes (`Ok(false)`).
    pub fn wait(&self, value: u64, timeout: Duration) -> GpuResult<bool> {
        let ctx = &self.inner.ctx;
        let semaphores = [self.inner.raw];
        let values = [value];
        let info = vk::SemaphoreWaitInfo::default()
            .semaphores(&semaphores)
            .values(&values);
        let nanos = u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX);
        // SAFETY: the semaphore is a live timeline semaphore of this device; `info` outlives
        // the call.
        match unsafe { ctx.device().wait_semaphores(&info, nanos) } {
            Ok(()) => Ok(true),
            Err(vk::Result::TIMEOUT) => Ok(false),
            Err(r) => Err(ctx.note_error(map_result("vkWaitSemaphores", r))),
        }
    }

    pub(crate) fn context(&self) -> &Context {
        &self.inner.ctx
    }
}

/// Where a hand-off stands; shared by the [`Handoff`] and its recorder's [`Ticket`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    /// Recorded, not yet submitted.
    Waiting,
    /// On the queue (at the given instant); it signals the timeline value when done.
    Submitted(Instant),
    /// The hand-off was dropped unsubmitted: its commands never run.
    Abandoned,
    /// The recorder took its command buffer back before it was submitted.
    Revoked,
}

type Shared = Arc<(Mutex<Stage>, Condvar)>;

/// An ended command buffer waiting for the queue's owner to submit it. Dropping it unsubmitted
/// abandons it (its recorder then reports [`GpuError::Cancelled`]).
pub struct Handoff {
    cmd: vk::CommandBuffer,
    timeline: Timeline,
    value: u64,
    stage: Shared,
}

impl std::fmt::Debug for Handoff {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Handoff")
            .field("timeline", &self.timeline)
            .field("value", &self.value)
            .finish()
    }
}

impl Handoff {
    /// The timeline value this work signals when it completes.
    pub fn value(&self) -> u64 {
        self.value
    }

    /// Submits the work on the context's queue. The caller must own the queue right now (the
    /// context's contract); the work signals [`Handoff::value`] on the timeline.
    pub fn submit(self) -> GpuResult<()> {
        let (lock, wake) = &*self.stage;
        let mut stage = lock.lock().unwrap_or_else(PoisonError::into_inner);
        if *stage != Stage::Waiting {
            return Err(GpuError::Invalid(format!(
                "hand-off to {} value {}: its recorder took it back",
                self.timeline.name(),
                self.value
            )));
        }
        // Held across the submission: the recorder cannot free the command buffer meanwhile.
        let result = submit_signalling(&self.timeline, self.cmd, self.value);
        *stage = if result.is_ok() {
            Stage::Submitted(Instant::now())
        } else {
            Stage::Abandoned
        };
        wake.notify_all();
        result
        // Drop sees a non-waiting stage and changes nothing.
    }
}

impl Drop for Handoff {
    fn drop(&mut self) {
        let (lock, wake) = &*self.stage;
        let mut stage = lock.lock().unwrap_or_else(PoisonError::into_inner);
        if *stage == Stage::Waiting {
            *stage = Stage::Abandoned;
            wake.notify_all();
        }
    }
}

/// The recorder's side of a [`Handoff`].
#[derive(Debug)]
pub(crate) struct Ticket {
    stage: Shared,
    timeline: Timeline,
    value: u64,
}

/// How a ticket ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Outcome {
    /// Submitted and complete; the device time is at most the wall time since submission.
    Done { since_submit: Duration },
    /// Never submitted: the command buffer may be reset.
    NeverRan,
}

/// Makes a hand-off of `cmd` (ended, executable) that signals `value` on `timeline`.
pub(crate) fn hand_off(
    cmd: vk::CommandBuffer,
    timeline: &Timeline,
    value: u64,
) -> (Handoff, Ticket) {
    let stage: Shared = Arc::new((Mutex::new(Stage::Waiting), Condvar::new()));
    (
        Handoff {
            cmd,
            timeline: timeline.clone(),
            value,
            stage: stage.clone(),
        },
        Ticket {
            stage,
            timeline: timeline.clone(),
            value,
        },
    )
}

impl Ticket {
    /// Blocks until the hand-off was submitted and its work complete, or abandoned.
    /// `timeout` bounds the device part only (the queue's owner may take its time).
    pub(crate) fn wait(&self, timeout: Duration, what: &str) -> GpuResult<Outcome> {
        let (lock, wake) = &*self.stage;
        let mut stage = lock.lock().unwrap_or_else(PoisonError::into_inner);
        while *stage == Stage::Waiting {
            stage = wake.wait(stage).unwrap_or_else(PoisonError::into_inner);
        }
        let at = match *stage {
            Stage::Submitted(at) => at,
            _ => return Ok(Outcome::NeverRan),
        };
        drop(stage);
        if self.timeline.wait(self.value, timeout)? {
            Ok(Outcome::Done {
                since_submit: at.elapsed(),
            })
        } else {
            Err(GpuError::Timeout {
                what: what.to_string(),
                timeout,
            })
        }
    }

    /// Takes the command buffer back if it was not submitted (`true`: it never runs); `false`
    /// when it is on the queue (wait for it before freeing it).
    pub(crate) fn revoke(&self) -> bool {
        let (lock, _) = &*self.stage;
        let mut stage = lock.lock().unwrap_or_else(PoisonError::into_inner);
        match *stage {
            Stage::Waiting => {
                *stage = Stage::Revoked;
                true
            }
            Stage::Submitted(_) => false,
            Stage::Abandoned | Stage::Revoked => true,
        }
    }

    /// Waits without a bound for submitted work (used by teardown).
    pub(crate) fn wait_forever(&self) {
        let _ = self.timeline.wait(self.value, Duration::MAX);
    }
}

/// One `vkQueueSubmit` of `cmd` signalling `value` on `timeline`, on the context's queue.
pub(crate) fn submit_signalling(
    timeline: &Timeline,
    cmd: vk::CommandBuffer,
    value: u64,
) -> GpuResult<()> {
    let buffers = [cmd];
    let semaphores = [timeline.raw()];
    let values = [value];
    let mut timeline_info =
        vk::TimelineSemaphoreSubmitInfo::default().signal_semaphore_values(&values);
    let submit = vk::SubmitInfo::default()
        .command_buffers(&buffers)
        .signal_semaphores(&semaphores)
        .push_next(&mut timeline_info);
    timeline.context().submit(&submit, vk::Fence::null())
}
