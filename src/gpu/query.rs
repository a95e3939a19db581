//! Timestamp queries for per-kernel profiling.

use std::sync::Arc;

use ash::vk;

use super::context::Context;
use super::error::{map_result, GpuError, GpuResult};

/// A pool of `count` GPU timestamps, written by [`super::Recorder::write_timestamp`] and read
/// back in nanoseconds. Cloning shares it (an `Arc`).
#[derive(Clone)]
pub struct TimestampPool {
    inner: Arc<QueryInner>,
}

struct QueryInner {
    ctx: Context,
    raw: vk::QueryPool,
    count: u32,
    name: String,
}

impl Drop for QueryInner {
    fn drop(&mut self) {
        // SAFETY: recorders keep a clone of the pool until their work is done, so no pending
        // command buffer uses it.
        unsafe { self.ctx.device().destroy_query_pool(self.raw, None) };
    }
}

impl std::fmt::Debug for TimestampPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TimestampPool")
            .field("name", &self.inner.name)
            .field("count", &self.inner.count)
            .finish()
    }
}

impl TimestampPool {
    /// A pool of `count` timestamps; [`GpuError::Unsupported`] if the compute queue cannot
    /// write timestamps.
    pub fn new(ctx: &Context, name: &str, count: u32) -> GpuResult<TimestampPool> {
        if !ctx.limits().timestamps {
            return Err(GpuError::Unsupported(format!(
                "{}: the compute queue cannot write timestamps",
                ctx.device_name()
            )));
        }
        if count == 0 {
            return Err(GpuError::Invalid(format!(
                "timestamp pool {name}: zero queries"
            )));
        }
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(count);
        // SAFETY: valid create info; destroyed in Drop.
        let raw = unsafe { ctx.device().create_query_pool(&info, None) }
            .map_err(|r| map_result("vkCreateQueryPool", r))?;
        ctx.set_name(raw, name);
        Ok(TimestampPool {
            inner: Arc::new(QueryInner {
                ctx: ctx.clone(),
                raw,
                count,
                name: name.to_string(),
            }),
        })
    }

    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// Number of timestamps.
    pub fn count(&self) -> u32 {
        self.inner.count
    }

    pub(crate) fn raw(&self) -> vk::QueryPool {
        self.inner.raw
    }

    /// Every timestamp in nanoseconds on the GPU's clock (only differences mean anything).
    /// Call after the recording that wrote them was submitted and waited for; a timestamp that
    /// was not written is an error (it is never waited for, so this cannot hang).
    pub fn read_ns(&self) -> GpuResult<Vec<u64>> {
        let ctx = &self.inner.ctx;
        let mut data = vec![[0u64; 2]; self.inner.count as usize];
        // SAFETY: `data` holds `count` (value, availability) pairs of u64, matching the flags.
        let result = unsafe {
            ctx.device().get_query_pool_results(
                self.inner.raw,
                0,
                &mut data,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WITH_AVAILABILITY,
            )
        };
        match result {
            Ok(()) | Err(vk::Result::NOT_READY) => {}
            Err(r) => return Err(map_result("vkGetQueryPoolResults", r)),
        }
        let limits = ctx.limits();
        let mask = match limits.timestamp_valid_bits {
            bits if bits >= 64 => u64::MAX,
            bits => (1u64 << bits) - 1,
        };
        let period = f64::from(limits.timestamp_period_ns);
        data.iter()
            .enumerate()
            .map(|(i, &[ticks, available])| {
                if available == 0 {
                    Err(GpuError::Invalid(format!(
                        "timestamp {i} of {} was not written by a completed submission",
                        self.inner.name
                    )))
                } else {
                    Ok(((ticks & mask) as f64 * period) as u64)
                }
            })
            .collect()
    }
}
