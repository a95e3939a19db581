//! Shared helper for tests that need Vulkan: a validated context, or a clean skip. With
//! `REQUIRE_VULKAN=1` (set in CI) a missing Vulkan fails the test instead of skipping it.

use foldfree::gpu::{Context, ContextDesc};

/// True when the environment demands a working Vulkan device (CI).
pub fn require_vulkan() -> bool {
    std::env::var("REQUIRE_VULKAN").is_ok_and(|v| v == "1")
}

/// A context with the validation layer on (and synchronization validation when
/// `FOLDFREE_SYNC_VALIDATION=1`). `None` when this machine has no usable Vulkan, after printing
/// "skipped: no Vulkan"; panics instead under `REQUIRE_VULKAN=1`, and for any error that is not
/// a missing-Vulkan one (those are bugs).
pub fn test_context() -> Option<Context> {
    let desc = ContextDesc {
        app_name: "foldfree-tests".to_string(),
        validation: true,
        ..ContextDesc::default()
    };
    match Context::new(&desc) {
        Ok(ctx) => Some(ctx),
        Err(e) if require_vulkan() => panic!("REQUIRE_VULKAN=1 but Vulkan is unavailable: {e}"),
        Err(e) if e.is_unavailable() => {
            eprintln!("skipped: no Vulkan ({e})");
            None
        }
        Err(e) => panic!("creating the Vulkan context failed: {e}"),
    }
}

/// Whether this machine has a usable Vulkan device ([`test_context`] succeeds): false after
/// printing "skipped: no Vulkan"; panics instead under `REQUIRE_VULKAN=1`.
pub fn vulkan_available() -> bool {
    test_context().is_some()
}

/// Fails the test if the validation layer said anything.
pub fn assert_no_validation_messages(messages: &[String], when: &str) {
    assert!(
        messages.is_empty(),
        "{} validation message(s) {when}:\n{}",
        messages.len(),
        messages.join("\n")
    );
}

/// Runs `body` with a validated context, then asserts that the validation layer stayed silent
/// both during the body and while the device was torn down (which reports leaked objects).
/// Everything `body` created must be dropped by the time it returns. Skips like
/// [`test_context`].
pub fn with_test_context(body: impl FnOnce(&Context)) {
    let Some(ctx) = test_context() else {
        return;
    };
    let log = ctx.message_log();
    body(&ctx);
    assert_no_validation_messages(&ctx.validation_messages(), "during the test");
    drop(ctx);
    assert_no_validation_messages(&log.messages(), "at teardown");
}
