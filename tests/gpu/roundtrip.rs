//! Round trips through the Vulkan layer on whatever device is present (lavapipe in CI), with the
//! validation layer on: every test also asserts that it produced no validation message.
//! Run with `FOLDFREE_SYNC_VALIDATION=1` to add synchronization validation.

use crate::common::gpu as gpu_common;

use std::time::{Duration, Instant};

use bytemuck::{Pod, Zeroable};
use foldfree::gpu::{
    shaders, Access, Buffer, BufferUsage, ComputePipeline, ComputePipelineDesc, Context,
    ContextDesc, DescriptorSet, GpuError, MemoryLocation, Recorder, Timeline, TimestampPool,
};
use gpu_common::with_test_context;

const TIMEOUT: Duration = Duration::from_secs(60);

/// Mirrors `Push` in glsl/test/saxpy.comp: `{ float a; uint n; }`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SaxpyPush {
    a: f32,
    n: u32,
}
const _: () = assert!(std::mem::size_of::<SaxpyPush>() == 8);

fn saxpy_pipeline(ctx: &Context) -> ComputePipeline {
    let words = shaders::words(shaders::TEST_SAXPY).expect("embedded SPIR-V");
    ComputePipeline::new(
        ctx,
        &ComputePipelineDesc::new(
            "test.saxpy",
            &words,
            2,
            std::mem::size_of::<SaxpyPush>() as u32,
        ),
    )
    .expect("saxpy pipeline")
}

/// Deterministic inputs without cancellation: x in [0, 1), y in [1, 2).
fn inputs(n: usize) -> (Vec<f32>, Vec<f32>) {
    let x = (0..n).map(|i| (i % 1013) as f32 / 1013.0).collect();
    let y = (0..n).map(|i| 1.0 + (i % 787) as f32 / 787.0).collect();
    (x, y)
}

fn assert_close(gpu: &[f32], cpu: &[f32]) {
    assert_eq!(gpu.len(), cpu.len());
    for (i, (&g, &c)) in gpu.iter().zip(cpu).enumerate() {
        let rel = ((g - c) / c.abs().max(1.0)).abs();
        assert!(
            rel <= 1e-6,
            "element {i}: gpu {g} vs cpu {c} (relative {rel:e})"
        );
    }
}

/// y ← a·x + y twice, with a read-write → read-write barrier between the dispatches, against the
/// same two steps on the CPU.
fn saxpy_twice(ctx: &Context, n: usize, staged: bool) {
    let (x, y) = inputs(n);
    let a = 2.5f32;
    let bytes = (n * 4) as u64;
    let xb = Buffer::new(
        ctx,
        "test.x",
        bytes,
        BufferUsage::Storage,
        MemoryLocation::GpuOnly,
    )
    .expect("x buffer");
    let yb = Buffer::new(
        ctx,
        "test.y",
        bytes,
        BufferUsage::Storage,
        MemoryLocation::GpuOnly,
    )
    .expect("y buffer");
    if staged {
        xb.upload_staged(&x).expect("upload x");
        yb.upload_staged(&y).expect("upload y");
    } else {
        xb.write(&x).expect("write x");
        yb.write(&y).expect("write y");
    }
    let pipeline = saxpy_pipeline(ctx);
    let set = DescriptorSet::new(&pipeline, "test.saxpy.set", &[&xb, &yb]).expect("set");

    let mut rec = Recorder::new(ctx, "test.saxpy").expect("recorder");
    rec.begin().expect("begin");
    rec.bind(&pipeline, &set);
    rec.push(&SaxpyPush { a, n: n as u32 });
    rec.dispatch_1d(n as u32);
    rec.barrier(Access::ComputeReadWrite, Access::ComputeReadWrite);
    rec.dispatch_1d(n as u32);
    rec.submit_and_wait(TIMEOUT).expect("submit");
    assert_eq!(rec.dispatch_count(), 2);

    let gpu: Vec<f32> = if staged {
        yb.download_staged().expect("download y")
    } else {
        yb.read().expect("read y")
    };
    let cpu: Vec<f32> = x
        .iter()
        .zip(&y)
        .map(|(&x, &y)| {
            let once = a * x + y;
            a * x + once
        })
        .collect();
    assert_close(&gpu, &cpu);
}

#[test]
fn saxpy_1000_elements_matches_cpu() {
    with_test_context(|ctx| saxpy_twice(ctx, 1000, false));
}

#[test]
fn saxpy_5m_elements_needs_a_2d_grid_and_matches_cpu() {
    with_test_context(|ctx| {
        // 5M threads / 64 = 78125 workgroups > 65535: only a 2-D grid covers them.
        let max_x = ctx.limits().max_compute_work_group_count[0];
        assert!(max_x >= 65535);
        saxpy_twice(ctx, 5_000_000, false);
    });
}

/// Regression: `global_index()` in glsl/common/grid.glsl reads `gl_WorkGroupSize`, which glslang
/// folds to 1 when the include precedes `layout(local_size_x = 64) in;`. Then every row of a 2-D
/// grid past the first overlapped the first row. Each index must be hit exactly once.
#[test]
fn dispatch_1d_grid_covers_every_index_exactly_once() {
    with_test_context(|ctx| {
        let words = shaders::words(shaders::TEST_GRID_COVER).expect("embedded SPIR-V");
        let pipeline = ComputePipeline::new(
            ctx,
            &ComputePipelineDesc::new("test.grid_cover", &words, 1, 4),
        )
        .expect("pipeline");
        let max_x = ctx.limits().max_compute_work_group_count[0] as usize;
        // Just past one full row of workgroups, so the grid needs two rows.
        for n in [1usize, 63, 65, 1000, max_x.min(1 << 20) * 64 + 1] {
            let hits = Buffer::new(
                ctx,
                "test.grid_cover.hits",
                (n * 4) as u64,
                BufferUsage::Storage,
                MemoryLocation::GpuOnly,
            )
            .expect("hits");
            let set = DescriptorSet::new(&pipeline, "test.grid_cover.set", &[&hits]).expect("set");
            let mut rec = Recorder::new(ctx, "test.grid_cover").expect("recorder");
            rec.begin().expect("begin");
            rec.fill_buffer(&hits, 0);
            rec.barrier(Access::TransferWrite, Access::ComputeReadWrite);
            rec.bind(&pipeline, &set);
            rec.push(&(n as u32));
            rec.dispatch_1d(n as u32);
            rec.submit_and_wait(TIMEOUT).expect("submit");
            let out: Vec<u32> = hits.read().expect("read");
            if let Some(i) = out.iter().position(|&h| h != 1) {
                panic!("n = {n}: index {i} was hit {} times", out[i]);
            }
        }
    });
}

#[test]
fn saxpy_through_staging_buffers_matches_cpu() {
    // The discrete-GPU path: upload and download by copies through staging buffers.
    with_test_context(|ctx| saxpy_twice(ctx, 100_003, true));
}

#[test]
fn storage_buffer_above_the_limit_is_refused_before_allocating() {
    with_test_context(|ctx| {
        let limit = ctx.limits().max_storage_buffer_range;
        let err = Buffer::new(
            ctx,
            "test.too_large",
            limit + 4,
            BufferUsage::Storage,
            MemoryLocation::GpuOnly,
        )
        .expect_err("over the limit");
        match err {
            GpuError::BufferTooLarge {
                name,
                bytes,
                limit: l,
            } => {
                assert_eq!(name, "test.too_large");
                assert_eq!(bytes, limit + 4);
                assert_eq!(l, limit);
            }
            other => panic!("expected BufferTooLarge, got {other}"),
        }
    });
}

#[test]
fn timestamps_around_a_dispatch_give_a_nonnegative_duration() {
    with_test_context(|ctx| {
        if !ctx.limits().timestamps {
            eprintln!("skipped: {} has no compute timestamps", ctx.device_name());
            return;
        }
        let n = 1 << 20;
        let (x, y) = inputs(n);
        let xb = Buffer::from_slice(ctx, "test.ts.x", &x).expect("x");
        let yb = Buffer::from_slice(ctx, "test.ts.y", &y).expect("y");
        let pipeline = saxpy_pipeline(ctx);
        let set = DescriptorSet::new(&pipeline, "test.ts.set", &[&xb, &yb]).expect("set");
        let pool = TimestampPool::new(ctx, "test.ts.pool", 2).expect("pool");
        let mut rec = Recorder::new(ctx, "test.ts").expect("recorder");
        // Twice, to check that a pool can be rewritten in a new recording.
        for _ in 0..2 {
            rec.begin().expect("begin");
            rec.write_timestamp(&pool, 0);
            rec.bind(&pipeline, &set);
            rec.push(&SaxpyPush {
                a: 1.0,
                n: n as u32,
            });
            rec.dispatch_1d(n as u32);
            rec.write_timestamp(&pool, 1);
            rec.submit_and_wait(TIMEOUT).expect("submit");
            let ts = pool.read_ns().expect("timestamps");
            assert_eq!(ts.len(), 2);
            assert!(ts[1] >= ts[0], "timestamps go backwards: {ts:?}");
            eprintln!(
                "saxpy over {n} floats: {} µs on the GPU clock",
                (ts[1] - ts[0]) / 1000
            );
        }
    });
}

/// A hand-off submitted on another thread signals its timeline value and the recorder's wait
/// returns; one dropped unsubmitted makes the wait report `Cancelled` and the recorder is
/// reusable; a recorder that takes its work back (`begin`) makes a late submit fail.
#[test]
fn handed_off_work_is_submitted_elsewhere_or_cancelled_cleanly() {
    with_test_context(|ctx| {
        let n = 1024usize;
        let a = Buffer::new(
            ctx,
            "test.handoff.a",
            (n * 4) as u64,
            BufferUsage::Storage,
            MemoryLocation::GpuToCpu,
        )
        .expect("a");
        let timeline = Timeline::new(ctx, "test.handoff.timeline").expect("timeline");
        assert_eq!(timeline.value().expect("value"), 0);
        let mut rec = Recorder::new(ctx, "test.handoff").expect("recorder");

        rec.begin().expect("begin");
        rec.fill_buffer(&a, 2.5f32.to_bits());
        let h = rec.hand_off(&timeline, 1).expect("hand off");
        assert_eq!(h.value(), 1);
        let owner = std::thread::spawn(move || h.submit());
        rec.wait(TIMEOUT)
            .expect("submitted elsewhere, then complete");
        owner.join().expect("owner thread").expect("submit");
        assert_eq!(timeline.value().expect("value"), 1);
        assert!(timeline.wait(1, TIMEOUT).expect("wait"));
        let out: Vec<f32> = a.read().expect("read");
        assert!(out.iter().all(|&v| v == 2.5));
        assert!(rec.last_latency().is_some());

        rec.begin().expect("begin");
        rec.fill_buffer(&a, 0);
        let h = rec.hand_off(&timeline, 2).expect("hand off");
        drop(h);
        assert!(matches!(rec.wait(TIMEOUT), Err(GpuError::Cancelled { .. })));
        assert_eq!(timeline.value().expect("value"), 1, "nothing ran");

        rec.begin().expect("begin");
        rec.fill_buffer(&a, 0);
        let h = rec.hand_off(&timeline, 2).expect("hand off");
        rec.begin().expect("takes the unsubmitted work back");
        assert!(matches!(h.submit(), Err(GpuError::Invalid(_))));
        rec.fill_buffer(&a, 1.0f32.to_bits());
        rec.submit_and_wait(TIMEOUT)
            .expect("the recorder still works");
        let out: Vec<f32> = a.read().expect("read");
        assert!(out.iter().all(|&v| v == 1.0));
    });
}

#[test]
fn fill_then_copy_round_trips() {
    with_test_context(|ctx| {
        let n = 4096usize;
        let a = Buffer::new(
            ctx,
            "test.fill.a",
            (n * 4) as u64,
            BufferUsage::Storage,
            MemoryLocation::GpuOnly,
        )
        .expect("a");
        let b = Buffer::new(
            ctx,
            "test.fill.b",
            (n * 4) as u64,
            BufferUsage::Staging,
            MemoryLocation::GpuToCpu,
        )
        .expect("b");
        let mut rec = Recorder::new(ctx, "test.fill").expect("recorder");
        rec.begin().expect("begin");
        rec.fill_buffer(&a, 1.5f32.to_bits());
        rec.barrier(Access::TransferWrite, Access::TransferRead);
        rec.copy_buffer(&a, &b, (n * 4) as u64);
        rec.submit_and_wait(TIMEOUT).expect("submit");
        let out: Vec<f32> = b.read().expect("read");
        assert!(out.iter().all(|&v| v == 1.5));
    });
}

#[test]
fn recording_mistakes_surface_at_submit_without_reaching_vulkan() {
    with_test_context(|ctx| {
        let mut rec = Recorder::new(ctx, "test.misuse").expect("recorder");
        rec.begin().expect("begin");
        rec.dispatch_1d(100); // no pipeline bound
        let err = rec.submit_and_wait(TIMEOUT).expect_err("misuse reported");
        assert!(matches!(err, GpuError::Invalid(_)), "{err}");
        // The recorder stays usable.
        rec.begin().expect("begin again");
        rec.submit_and_wait(TIMEOUT).expect("empty submit");
        // Submitting without begin is an error, not a Vulkan call.
        assert!(rec.submit_and_wait(TIMEOUT).is_err());
    });
}

#[test]
fn unknown_device_name_lists_the_available_devices() {
    if std::env::var_os(foldfree::gpu::DEVICE_ENV).is_some() {
        eprintln!("skipped: {} is set", foldfree::gpu::DEVICE_ENV);
        return;
    }
    // Only meaningful where Vulkan works at all.
    let Some(ctx) = gpu_common::test_context() else {
        return;
    };
    let real_name = ctx.device_name().to_string();
    drop(ctx);
    let desc = ContextDesc {
        device: Some("no-such-device-xyz".into()),
        ..ContextDesc::default()
    };
    match Context::new(&desc) {
        Err(GpuError::NoSuchDevice(msg)) => {
            assert!(msg.contains(&real_name), "{msg}");
        }
        Err(e) => panic!("expected NoSuchDevice, got {e}"),
        Ok(_) => panic!("a device matched a made-up name"),
    }
}

#[test]
fn measure_context_and_dispatch_overhead() {
    // Timings without validation (the numbers with it mean little); prints, asserts nothing
    // about speed.
    if gpu_common::test_context().is_none() {
        return;
    }
    let start = Instant::now();
    let ctx = Context::new(&ContextDesc::default()).expect("context");
    let created = start.elapsed();
    let n = 64usize;
    let (x, y) = inputs(n);
    let xb = Buffer::from_slice(&ctx, "bench.x", &x).expect("x");
    let yb = Buffer::from_slice(&ctx, "bench.y", &y).expect("y");
    let t = Instant::now();
    let pipeline = saxpy_pipeline(&ctx);
    let pipeline_time = t.elapsed();
    let set = DescriptorSet::new(&pipeline, "bench.set", &[&xb, &yb]).expect("set");
    let mut rec = Recorder::new(&ctx, "bench").expect("recorder");

    let submits = 200;
    let t = Instant::now();
    for _ in 0..submits {
        rec.begin().expect("begin");
        rec.submit_and_wait(TIMEOUT).expect("submit");
    }
    let per_submit = t.elapsed() / submits;

    let dispatches = 2000u32;
    rec.begin().expect("begin");
    rec.bind(&pipeline, &set);
    rec.push(&SaxpyPush {
        a: 1e-3,
        n: n as u32,
    });
    for _ in 0..dispatches {
        rec.dispatch_1d(n as u32);
        rec.barrier(Access::ComputeReadWrite, Access::ComputeReadWrite);
    }
    let t = Instant::now();
    rec.submit_and_wait(TIMEOUT).expect("submit");
    let per_dispatch = t.elapsed() / dispatches;
    eprintln!(
        "{} ({}): context {:.1} ms (Context::new reports {:.1} ms), pipeline {:.2} ms, \
         empty submit+wait {:.1} µs, dispatch+barrier {:.1} µs",
        ctx.device_name(),
        ctx.device_type_name(),
        created.as_secs_f64() * 1e3,
        ctx.creation_time().as_secs_f64() * 1e3,
        pipeline_time.as_secs_f64() * 1e3,
        per_submit.as_secs_f64() * 1e6,
        per_dispatch.as_secs_f64() * 1e6,
    );
}

/// The "no validation message" checks above are only worth something if messages do arrive:
/// a fill followed by a dispatch without a barrier must be reported by synchronization
/// validation (lavapipe itself computes the right answer either way).
#[test]
fn missing_barrier_is_reported_by_sync_validation() {
    let Some(probe) = gpu_common::test_context() else {
        return;
    };
    drop(probe);
    let ctx = Context::new(&ContextDesc {
        validation: true,
        sync_validation: true,
        ..ContextDesc::default()
    })
    .expect("context with synchronization validation");
    let words = shaders::words(shaders::TEST_GRID_COVER).expect("embedded SPIR-V");
    let pipeline =
        ComputePipeline::new(&ctx, &ComputePipelineDesc::new("test.hazard", &words, 1, 4))
            .expect("pipeline");
    let hits = Buffer::new(
        &ctx,
        "test.hazard.hits",
        256,
        BufferUsage::Storage,
        MemoryLocation::GpuOnly,
    )
    .expect("hits");
    let set = DescriptorSet::new(&pipeline, "test.hazard.set", &[&hits]).expect("set");
    let mut rec = Recorder::new(&ctx, "test.hazard").expect("recorder");
    rec.begin().expect("begin");
    rec.fill_buffer(&hits, 0);
    // Deliberately no barrier(TransferWrite, ComputeReadWrite) here.
    rec.bind(&pipeline, &set);
    rec.push(&64u32);
    rec.dispatch_1d(64);
    rec.submit_and_wait(TIMEOUT).expect("submit");
    let messages = ctx.take_validation_messages();
    assert!(
        messages
            .iter()
            .any(|m| m.contains("SYNC-HAZARD") && m.contains("test.hazard.hits")),
        "expected a hazard naming the buffer, got {messages:?}"
    );
}
