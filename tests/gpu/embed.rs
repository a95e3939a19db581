//! Embedding in a host's Vulkan renderer (`foldfree::embed`), under the Khronos validation layer
//! (plus synchronization validation with `FOLDFREE_SYNC_VALIDATION=1`): the host is
//! `examples/host_renderer.rs`, included as a module, with its own instance, device, queue,
//! buffers and debug messenger. Any validation message fails. Skips without Vulkan unless
//! `REQUIRE_VULKAN=1`.

#[path = "../../examples/host_renderer.rs"]
#[allow(dead_code)]
mod host_renderer;

use std::path::PathBuf;
use std::process::Command;

use foldfree::embed::{
    gather_words, EmbedOptions, Engine, ForeignBuffer, HostAccess, JobOptions, JobPhase, JobQueue,
    MeshBuffers, UvFormat, UvTarget, MEMORY_FILE,
};
use foldfree::gpu::{vk, Context};
use host_renderer::{Host, Unavailable};

use crate::common::gpu::require_vulkan;

/// The host with validation on, or `None` (skip) when this machine has no usable Vulkan.
fn validated_host() -> Option<Host> {
    let sync = std::env::var(foldfree::gpu::SYNC_VALIDATION_ENV).is_ok_and(|v| v == "1");
    match Host::new(true, sync) {
        Ok(h) => Some(h),
        Err(e) if require_vulkan() => panic!("REQUIRE_VULKAN=1 but Vulkan is unavailable: {e}"),
        Err(e) if e.downcast_ref::<Unavailable>().is_some() => {
            eprintln!("skipped: {e}");
            None
        }
        Err(e) => panic!("creating the host failed: {e}"),
    }
}

/// Whether two UVs are the same bit for bit.
fn same_bits(a: &[f64; 2], b: &[f64; 2]) -> bool {
    a[0].to_bits() == b[0].to_bits() && a[1].to_bits() == b[1].to_bits()
}

/// An engine on the host's device and queue.
fn engine_on(host: &Host) -> Engine {
    // SAFETY: the handles come from `host`, which outlives the engine (every test drops the
    // engine first); the device has `required_features()`; the tests use the queue only
    // through the engine, its jobs' `poll`/`finish` on the test's thread, or between them.
    let ctx = unsafe { Context::from_host(host.host_desc()) }.expect("context");
    Engine::new(ctx).expect("engine")
}

fn assert_silent(host: &Host, when: &str) {
    let messages = host.take_messages();
    assert!(
        messages.is_empty(),
        "{} validation message(s) {when}:\n{}",
        messages.len(),
        messages.join("\n")
    );
}

/// The `vt` lines of an OBJ.
fn parse_vt(text: &str) -> Vec<[f64; 2]> {
    text.lines()
        .filter_map(|l| l.strip_prefix("vt "))
        .map(|rest| {
            let v: Vec<f64> = rest
                .split_whitespace()
                .map(|x| x.parse().expect("a vt coordinate"))
                .collect();
            [v[0], v[1]]
        })
        .collect()
}

/// The CLI's UVs for `mesh` with the Vulkan backend and default options.
fn cli_uv(mesh: &std::path::Path) -> Vec<[f64; 2]> {
    let dir = std::env::temp_dir().join(format!("foldfree-embed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let out = dir.join("camel.out.obj");
    let run = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("param")
        .arg(mesh)
        .arg("-o")
        .arg(&out)
        .args(["--backend", "vulkan"])
        .output()
        .expect("run foldfree");
    // The engine keeps its best map whether or not the budget sufficed; so does the CLI (exit 3).
    let kept = run.status.code() == Some(3)
        && String::from_utf8_lossy(&run.stderr).contains("best flip-free map was written");
    assert!(
        run.status.success() || kept,
        "foldfree param failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(&out).expect("read the CLI's output");
    let _ = std::fs::remove_dir_all(&dir);
    parse_vt(&text)
}

/// Both ways of writing UVs put exactly the engine's UVs (rounded to f32) into the host's
/// interleaved vertex buffer, leave the positions alone, agree with the CLI, raise no
/// validation message, and leave the host's device working after the engine is dropped.
#[test]
fn host_buffer_receives_the_engines_uvs_which_match_the_cli() {
    let Some(host) = validated_host() else {
        return;
    };
    let mesh_path: PathBuf = host_renderer::default_mesh();
    let mesh = foldfree::mesh::read_obj(&mesh_path).expect("read the camel");
    let out = host_renderer::run(&host, &mesh).expect("the host flow");
    assert_silent(&host, "during the host flow");

    let n = mesh.positions.len();
    assert_eq!(out.uv.len(), n);
    assert!(out.uv.iter().all(|p| p[0].is_finite() && p[1].is_finite()));
    let as_f32: Vec<[f32; 2]> = out.uv.iter().map(|p| [p[0] as f32, p[1] as f32]).collect();
    assert_eq!(
        out.uv_submitted, as_f32,
        "UVs written by the engine's submission"
    );
    assert_eq!(
        out.uv_recorded, as_f32,
        "UVs recorded into the host's command buffer"
    );
    assert!(
        out.positions_intact,
        "the engine wrote outside the UV slots"
    );

    let cli = cli_uv(&mesh_path);
    assert_eq!(cli.len(), n, "one vt per vertex");
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &cli {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let worst = out
        .uv
        .iter()
        .zip(&cli)
        .map(|(a, b)| (a[0] - b[0]).abs().max((a[1] - b[1]).abs()))
        .fold(0.0f64, f64::max);
    assert!(
        worst <= 1e-5 * size,
        "engine vs CLI: max |diff| {worst:e} over a UV box of {size}"
    );
    drop(host);
}

/// A misaligned or too-small target is refused before any GPU work: the host's bytes stay as
/// they were and validation stays silent. A bad in-memory mesh is refused like a bad file.
#[test]
fn bad_targets_are_refused_without_touching_the_host_buffer() {
    let Some(host) = validated_host() else {
        return;
    };
    let buffer = host
        .create_buffer(64, vk::BufferUsageFlags::STORAGE_BUFFER)
        .expect("host buffer");
    host.write_buffer(&buffer, &[0xABu8; 64]);
    {
        let engine = engine_on(&host);
        let uv = vec![[0.25, 0.5]; 4];
        let target = |offset, stride| UvTarget {
            // SAFETY: a live 64-byte storage buffer of the lent device, destroyed after the
            // engine is dropped.
            buffer: unsafe { ForeignBuffer::new(buffer.raw, buffer.size) },
            offset,
            stride,
            format: UvFormat::F32x2,
        };
        for (offset, stride) in [(2, 8), (0, 6), (0, 4), (40, 8)] {
            let e = engine
                .write_uvs(&uv, &target(offset, stride))
                .expect_err("refused");
            assert!(matches!(e, foldfree::Error::Usage(_)), "{e}");
        }
        assert_eq!(host.read_buffer::<u8>(&buffer), vec![0xAB; 64]);
        // In-memory meshes go through the CLI's validation; errors name "<memory>".
        let e = engine
            .parameterize(
                &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                &[[0, 1, 3]],
                &EmbedOptions::default(),
            )
            .expect_err("face index out of range");
        assert!(matches!(e, foldfree::Error::Mesh(_)), "{e}");
        assert!(e.to_string().contains(MEMORY_FILE), "{e}");
        // The last layout that fits: 4 UVs ending at byte 64.
        engine.write_uvs(&uv, &target(32, 8)).expect("fits");
        let words = host.read_buffer::<f32>(&buffer);
        assert_eq!(&words[8..], &[0.25, 0.5, 0.25, 0.5, 0.25, 0.5, 0.25, 0.5]);
        assert_eq!(host.read_buffer::<u8>(&buffer)[..32], [0xAB; 32]);
    }
    host.destroy_buffer(buffer);
    assert_silent(&host, "while refusing bad targets");
}

/// After a device loss (simulated: a real one cannot be provoked on demand) every engine call
/// returns `GpuError::DeviceLost` — no panic, no hang — and dropping the engine leaves the host's
/// device usable and validation silent.
#[test]
fn a_lost_device_gives_typed_errors_not_panics() {
    let Some(host) = validated_host() else {
        return;
    };
    let buffer = host
        .create_buffer(64, vk::BufferUsageFlags::STORAGE_BUFFER)
        .expect("host buffer");
    {
        let engine = engine_on(&host);
        let positions = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.2],
            [0.0, 1.0, 0.0],
        ];
        let faces = [[0, 1, 2], [0, 2, 3]];
        let opts = EmbedOptions::default();
        let uv = engine
            .parameterize(&positions, &faces, &opts)
            .expect("before the loss");
        assert!(!engine.context().is_lost());

        engine.context().simulate_device_lost();
        assert!(engine.context().is_lost());
        let lost = |e: foldfree::Error| {
            assert!(
                matches!(
                    e,
                    foldfree::Error::Gpu(foldfree::gpu::GpuError::DeviceLost { .. })
                ),
                "{e}"
            );
        };
        lost(
            engine
                .parameterize(&positions, &faces, &opts)
                .expect_err("parameterize after the loss"),
        );
        let target = UvTarget {
            // SAFETY: a live 64-byte storage buffer of the lent device, destroyed after the
            // engine is dropped.
            buffer: unsafe { ForeignBuffer::new(buffer.raw, buffer.size) },
            offset: 0,
            stride: 8,
            format: UvFormat::F32x2,
        };
        lost(
            engine
                .write_uvs(&uv, &target)
                .expect_err("write_uvs after the loss"),
        );
    }
    host.destroy_buffer(buffer);
    assert_silent(&host, "around the simulated loss");
}

/// The mesh gather kernel (`glsl/embed/gather_words.comp`) against its CPU twin
/// (`embed::gather_words`) on random words at several offsets and strides — including offsets
/// that are not a multiple of the descriptor alignment — and `parameterize_buffers` equal to
/// `parameterize` of the same (f32) mesh.
#[test]
fn mesh_from_host_buffers_matches_the_cpu_twin() {
    let Some(host) = validated_host() else {
        return;
    };
    let mut state = 0x2545_f491_u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 33) as u32
    };
    let words: Vec<u32> = (0..4096)
        .map(|_| ((next() % 2_000_001) as f32 / 1000.0 - 1000.0).to_bits())
        .collect();
    let buffer = host
        .create_buffer(4 * words.len() as u64, vk::BufferUsageFlags::STORAGE_BUFFER)
        .expect("host buffer");
    host.write_buffer(&buffer, &words);
    let grid_positions: Vec<[f64; 3]> = (0..16)
        .map(|i| {
            [
                f64::from(i % 4) * 0.3,
                f64::from(i / 4) * 0.3,
                0.01 * f64::from(i),
            ]
        })
        .collect();
    let mut grid_faces = Vec::new();
    for j in 0..3u32 {
        for i in 0..3u32 {
            let a = 4 * j + i;
            grid_faces.push([a, a + 1, a + 5]);
            grid_faces.push([a, a + 5, a + 4]);
        }
    }
    // Interleaved x y z u v (20 bytes) after a 36-byte header; indices after 100 bytes.
    let mut vb: Vec<f32> = vec![0.0; 9];
    for p in &grid_positions {
        vb.extend([p[0] as f32, p[1] as f32, p[2] as f32, 0.0, 0.0]);
    }
    let mut ib: Vec<u32> = vec![0; 25];
    ib.extend(grid_faces.iter().flatten());
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
    let vbuf = host.create_buffer(4 * vb.len() as u64, usage).expect("vb");
    let ibuf = host.create_buffer(4 * ib.len() as u64, usage).expect("ib");
    host.write_buffer(&vbuf, &vb);
    host.write_buffer(&ibuf, &ib);
    {
        let engine = engine_on(&host);
        // SAFETY: live storage buffers of the lent device, destroyed after the engine.
        let (fb, fv, fi) = unsafe {
            (
                ForeignBuffer::new(buffer.raw, buffer.size),
                ForeignBuffer::new(vbuf.raw, vbuf.size),
                ForeignBuffer::new(ibuf.raw, ibuf.size),
            )
        };
        for (offset, stride, n) in [
            (0u64, 12u64, 300u32),
            (4, 16, 200),
            (52, 28, 100),
            (8, 12, 1),
        ] {
            let src = MeshBuffers {
                positions: fb,
                position_offset: offset,
                position_stride: stride,
                vertex_count: n,
                indices: fb,
                index_offset: offset + 8,
                face_count: n / 2,
                before: HostAccess::any(),
            };
            let got = engine.read_mesh(&src).expect("gather");
            let twin_p = gather_words(
                &words,
                n as usize,
                offset as usize / 4,
                stride as usize / 4,
                3,
            )
            .expect("twin positions");
            let twin_i = gather_words(&words, n as usize / 2, offset as usize / 4 + 2, 3, 3)
                .expect("twin indices");
            let got_p: Vec<u32> = got
                .positions
                .iter()
                .flatten()
                .map(|&x| (x as f32).to_bits())
                .collect();
            let got_i: Vec<u32> = got.faces.iter().flatten().copied().collect();
            assert_eq!(
                got_p, twin_p,
                "positions at offset {offset} stride {stride}"
            );
            assert_eq!(got_i, twin_i, "indices at offset {offset}");
        }
        // Past the end of the buffer: refused before any GPU work.
        let too_far = MeshBuffers {
            positions: fb,
            position_offset: 0,
            position_stride: 16,
            vertex_count: 1025,
            indices: fb,
            index_offset: 0,
            face_count: 1,
            before: HostAccess::any(),
        };
        assert!(matches!(
            engine.read_mesh(&too_far),
            Err(foldfree::Error::Usage(_))
        ));

        let src = MeshBuffers {
            positions: fv,
            position_offset: 36,
            position_stride: 20,
            vertex_count: grid_positions.len() as u32,
            indices: fi,
            index_offset: 100,
            face_count: grid_faces.len() as u32,
            before: HostAccess::any(),
        };
        let mesh = engine.read_mesh(&src).expect("read the grid");
        let rounded: Vec<[f64; 3]> = grid_positions
            .iter()
            .map(|p| p.map(|c| f64::from(c as f32)))
            .collect();
        assert_eq!(mesh.positions, rounded);
        assert_eq!(mesh.faces, grid_faces);
        let opts = EmbedOptions::default();
        let from_buffers = engine
            .parameterize_buffers(&src, &opts)
            .expect("from buffers");
        let from_slices = engine
            .parameterize(&rounded, &grid_faces, &opts)
            .expect("from slices");
        assert_eq!(from_buffers, from_slices);
    }
    host.destroy_buffer(buffer);
    host.destroy_buffer(vbuf);
    host.destroy_buffer(ibuf);
    assert_silent(&host, "while gathering meshes from host buffers");
}

/// A job on the host's queue, advanced by `poll()` alone with 1 ms slices, gives the blocking
/// call's UVs bit for bit (slicing changes no arithmetic); it ran in many more slices than
/// residual checks; every submitted slice has signalled; validation stays silent.
#[test]
fn a_job_polled_to_completion_matches_the_blocking_call() {
    let Some(host) = validated_host() else {
        return;
    };
    let mesh = foldfree::mesh::read_obj(&host_renderer::default_mesh()).expect("mesh");
    let engine = engine_on(&host);
    let opts = EmbedOptions::default();
    let blocking = engine
        .parameterize(&mesh.positions, &mesh.faces, &opts)
        .expect("blocking call");
    let sliced = JobOptions {
        queue: JobQueue::BetweenFrames,
        slice_budget: std::time::Duration::from_millis(1),
    };
    let mut job = engine
        .start_parameterize(&mesh.positions, &mesh.faces, &opts, &sliced)
        .expect("start");
    let mut polls = 0u64;
    while !job.poll() {
        polls += 1;
        // A host's frame would go here.
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
    let p = job.progress();
    assert_eq!(p.phase, JobPhase::Done);
    assert!(p.iterations > 0 && p.slices > 1, "{p:?}");
    let checks = p.iterations.div_ceil(opts.admm.check_every as u64);
    assert!(p.slices > checks, "slices {} vs checks {checks}", p.slices);
    assert!(polls >= p.slices, "every slice needed a poll");
    assert_eq!(
        job.timeline().value().expect("timeline"),
        job.submitted_value()
    );
    let uv = job.finish().expect("job result");
    assert_eq!(uv.len(), blocking.len());
    for (i, (a, b)) in uv.iter().zip(&blocking).enumerate() {
        assert!(same_bits(a, b), "vertex {i}: job {a:?} vs blocking {b:?}");
    }

    // Slices far below one iteration's time: every iteration is split into kernel ranges,
    // still the same arithmetic.
    let mut short = EmbedOptions::default();
    short.admm.max_iters = 40;
    let blocking = engine
        .parameterize(&mesh.positions, &mesh.faces, &short)
        .expect("blocking call");
    let tiny = JobOptions {
        slice_budget: std::time::Duration::from_micros(100),
        ..sliced
    };
    let mut job = engine
        .start_parameterize(&mesh.positions, &mesh.faces, &short, &tiny)
        .expect("start");
    while !job.poll() {}
    let p = job.progress();
    assert!(
        p.slices > 3 * p.iterations,
        "iterations were not split: {p:?}"
    );
    let uv = job.finish().expect("job result");
    assert!(uv.iter().zip(&blocking).all(|(a, b)| same_bits(a, b)));
    drop(engine);
    assert_silent(&host, "running a job by poll()");
}

/// Cancelling mid-way: when `cancel` returns, every submitted slice has completed (the device
/// holds none of the job's work), the host's allocator holds none of the engine's memory,
/// the queue works for the host, and the validation layer saw nothing (no object destroyed in
/// use, no leak at teardown).
#[test]
fn cancelling_a_job_leaves_the_device_idle_and_frees_everything() {
    use foldfree::gpu::gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
    let Some(host) = validated_host() else {
        return;
    };
    let mesh = foldfree::mesh::read_obj(&host_renderer::default_mesh()).expect("mesh");
    let mut desc = host.host_desc();
    let allocator = std::sync::Arc::new(std::sync::Mutex::new(
        Allocator::new(&AllocatorCreateDesc {
            instance: desc.instance.clone(),
            device: desc.device.clone(),
            physical_device: desc.physical_device,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })
        .expect("host allocator"),
    ));
    desc.allocator = Some(allocator.clone());
    let live = || {
        allocator
            .lock()
            .expect("allocator")
            .generate_report()
            .allocations
            .len()
    };
    // SAFETY: as above; the allocator was made for this device.
    let ctx = unsafe { Context::from_host(desc) }.expect("context");
    let engine = Engine::new(ctx).expect("engine");
    let sliced = JobOptions {
        queue: JobQueue::BetweenFrames,
        slice_budget: std::time::Duration::from_millis(1),
    };
    let mut job = engine
        .start_parameterize(
            &mesh.positions,
            &mesh.faces,
            &EmbedOptions::default(),
            &sliced,
        )
        .expect("start");
    let t = std::time::Instant::now();
    while job.progress().iterations < 30 {
        assert!(!job.poll(), "the job finished before it could be cancelled");
        assert!(t.elapsed().as_secs() < 120, "no progress");
    }
    assert!(live() > 0, "the running job holds device buffers");
    let timeline = job.timeline().clone();
    let last = job.cancel();
    assert!(last.submitted_value > 0);
    assert_eq!(
        timeline.value().expect("timeline"),
        last.submitted_value,
        "a submitted slice was still running after cancel()"
    );
    drop(timeline);
    assert_eq!(live(), 0, "the cancelled job left allocations behind");
    drop(engine);
    let fill = host
        .create_buffer(16, vk::BufferUsageFlags::TRANSFER_DST)
        .expect("buffer");
    host.submit_once(|cmd| {
        // SAFETY: recording; the buffer is live with TRANSFER_DST usage; the range is inside.
        unsafe { host.device.cmd_fill_buffer(cmd, fill.raw, 0, 16, 9) };
        Ok(())
    })
    .expect("the host's queue works after the cancel");
    assert_eq!(host.read_buffer::<u32>(&fill), vec![9; 4]);
    host.destroy_buffer(fill);
    drop(allocator);
    assert_silent(&host, "cancelling a job");
}

/// A job on a queue of its own (`JobQueue::Own`, slices submitted by the job) gives the same UVs
/// as the blocking call; meanwhile the host orders a submission of its own after the job's
/// latest slice by waiting on the job's timeline semaphore in that submission (no CPU wait on
/// the job). Synchronization validation stays silent.
#[test]
fn a_job_on_its_own_queue_matches_and_the_host_can_wait_on_its_timeline() {
    let Some(host) = validated_host() else {
        return;
    };
    let mesh = foldfree::mesh::read_obj(&host_renderer::default_mesh()).expect("mesh");
    let engine = engine_on(&host);
    let mut opts = EmbedOptions::default();
    opts.admm.max_iters = 200;
    let blocking = engine
        .parameterize(&mesh.positions, &mesh.faces, &opts)
        .expect("blocking call");
    let own = JobOptions {
        queue: JobQueue::Own,
        slice_budget: std::time::Duration::from_millis(1),
    };
    let mut job = engine
        .start_parameterize(&mesh.positions, &mesh.faces, &opts, &own)
        .expect("start");
    let t = std::time::Instant::now();
    while job.submitted_value() == 0 {
        assert!(!job.poll() || job.submitted_value() > 0);
        assert!(t.elapsed().as_secs() < 120, "no slice was submitted");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let uv = job.finish().expect("job result");
    assert!(uv.iter().zip(&blocking).all(|(a, b)| same_bits(a, b)));

    // The host's queue is the job's only while it runs (a real host would lend a dedicated
    // queue); now a BetweenFrames job, and a host submission that waits on its timeline.
    let sliced = JobOptions {
        queue: JobQueue::BetweenFrames,
        slice_budget: std::time::Duration::from_millis(1),
    };
    let mut job = engine
        .start_parameterize(&mesh.positions, &mesh.faces, &opts, &sliced)
        .expect("start");
    while job.submitted_value() < 3 {
        assert!(!job.poll(), "finished before three slices");
    }
    let fill = host
        .create_buffer(16, vk::BufferUsageFlags::TRANSFER_DST)
        .expect("buffer");
    let wait = (job.timeline().raw(), job.submitted_value());
    host.submit_after(Some(wait), |cmd| {
        // SAFETY: recording; the buffer is live with TRANSFER_DST usage; the range is inside.
        unsafe { host.device.cmd_fill_buffer(cmd, fill.raw, 0, 16, 5) };
        Ok(())
    })
    .expect("a host submission waiting on the job's timeline");
    assert!(job.timeline().value().expect("value") >= wait.1);
    assert_eq!(host.read_buffer::<u32>(&fill), vec![5; 4]);
    host.destroy_buffer(fill);
    let uv = job.finish().expect("job result");
    assert!(uv.iter().zip(&blocking).all(|(a, b)| same_bits(a, b)));
    drop(engine);
    assert_silent(
        &host,
        "a job on its own queue, a host waiting on its timeline",
    );
}
