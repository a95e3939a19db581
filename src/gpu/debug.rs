//! The `VK_EXT_debug_utils` messenger: collects validation warnings and errors so that tests can
//! turn them into failures (a validation message is a bug even when lavapipe computes the right
//! numbers — it hides missing barriers).

use std::ffi::{c_void, CStr};
use std::sync::{Arc, Mutex, PoisonError};

use ash::vk;

/// A shared list of validation messages. Cloning shares the list; it outlives the [`Context`]
/// it came from, so a test can check what the layer said while the device was torn down.
///
/// [`Context`]: super::Context
#[derive(Clone, Debug, Default)]
pub struct MessageLog(Arc<Mutex<Vec<String>>>);

impl MessageLog {
    /// A copy of every message so far.
    pub fn messages(&self) -> Vec<String> {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Every message so far, leaving the log empty.
    pub fn take(&self) -> Vec<String> {
        std::mem::take(&mut *self.0.lock().unwrap_or_else(PoisonError::into_inner))
    }

    fn push(&self, message: String) {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(message);
    }

    /// The pointer handed to Vulkan as `pUserData`. It stays valid as long as one clone of this
    /// log lives; the context keeps one until after the messenger and instance are destroyed.
    fn user_data(&self) -> *mut c_void {
        Arc::as_ptr(&self.0).cast_mut().cast()
    }
}

/// Create-info of a messenger that pushes WARNING and ERROR messages of every type into `log`.
/// Used both for the long-lived messenger and chained into `VkInstanceCreateInfo`, which covers
/// instance creation and destruction.
pub(crate) fn messenger_info(log: &MessageLog) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(collect))
        .user_data(log.user_data())
}

fn severity_name(severity: vk::DebugUtilsMessageSeverityFlagsEXT) -> &'static str {
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        "ERROR"
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING) {
        "WARNING"
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::INFO) {
        "INFO"
    } else {
        "VERBOSE"
    }
}

fn type_name(types: vk::DebugUtilsMessageTypeFlagsEXT) -> &'static str {
    if types.contains(vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION) {
        "validation"
    } else if types.contains(vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE) {
        "performance"
    } else {
        "general"
    }
}

fn lossy(s: Option<&CStr>) -> String {
    s.map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The messenger callback. It must not unwind into the driver, so it only formats and pushes.
unsafe extern "system" fn collect(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if user.is_null() || data.is_null() {
        return vk::FALSE;
    }
    // SAFETY: `user` is `MessageLog::user_data` of a log whose Arc the context keeps alive until
    // after the messenger and the instance (the only callers) are destroyed.
    let log = unsafe { &*user.cast_const().cast::<Mutex<Vec<String>>>() };
    // SAFETY: the layer passes a valid callback-data struct that lives for the call.
    let data = unsafe { &*data };
    // SAFETY: `pMessageIdName` is null or a NUL-terminated string valid for the call.
    let id = lossy(unsafe { data.message_id_name_as_c_str() });
    // SAFETY: `pMessage` is null or a NUL-terminated string valid for the call.
    let message = lossy(unsafe { data.message_as_c_str() });
    let line = format!(
        "[{} {}] {id}: {message}",
        severity_name(severity),
        type_name(types)
    );
    if std::env::var_os("FOLDFREE_VK_ECHO").is_some() {
        eprintln!("{line}");
    }
    log.lock()
        .unwrap_or_else(PoisonError::into_inner)
        .push(line);
    vk::FALSE
}

impl MessageLog {
    /// Records a message produced by this layer itself (e.g. a leak noticed at teardown).
    pub(crate) fn note(&self, message: String) {
        self.push(message);
    }
}
