//! The C ABI of ballbar machine plugins, version [`ABI_VERSION`]. std only, so that a plugin
//! depends on nothing but this crate and the host reads the same layout.
//!
//! # The contract
//! A plugin is a shared library (`cdylib`) that exports **one** symbol,
//! [`DECLARATION_SYMBOL`]: a static [`PluginDeclaration`]. The host reads its first two fields
//! (ABI version, struct size) before anything else and refuses the library unless they match;
//! only then does it read the name and version and call the functions.
//!
//! Only `#[repr(C)]` data and `extern "C"` functions cross. Structured data crosses as RON
//! text: [`PluginDeclaration::describe`] returns the machine description (a
//! `ballbar_model::machine::MachineSpec` in RON). A plugin that builds machines from user files
//! (flag [`FLAG_MACHINE_FILE`]) receives the file's text as `describe`'s input.
//!
//! Error-term kernels: a plugin may declare named kernels ([`KernelDeclaration`]) that
//! evaluate a basis function (a 6-vector error motion per unit coefficient) for a batch of
//! joint states into a caller-owned buffer ([`PluginDeclaration::evaluate`]); the machine
//! description refers to them by name, and they take part in fitting like built-in terms.
//!
//! Memory: a buffer that the plugin allocates ([`OwnedBuffer`]) is freed by the plugin's own
//! [`PluginDeclaration::free_buffer`]; buffers the host passes in are the host's. Panics never
//! cross: every exported function catches them and returns [`STATUS_PANIC`] with the message.
//! The host never unloads a library it has loaded.
//!
//! # Writing a plugin
//! ```text
//! fn describe(_input: &str) -> Result<String, String> { Ok(MY_MACHINE_RON.to_string()) }
//! fn thermal_x(states: &[RawJointState], out: &mut [[f64; 6]]) -> Result<(), String> { ... }
//! ballbar_plugin_api::declare_plugin! {
//!     name: "my-machine",
//!     version: env!("CARGO_PKG_VERSION"),
//!     flags: 0,
//!     describe: describe,
//!     kernels: [("thermal_x", thermal_x)],
//! }
//! ```
//! `docs/plugins.md` walks through a complete out-of-tree plugin.

// This crate is the FFI boundary: it declares the `#[repr(C)]` layout and the helpers that
// cross it (raw pointers, `extern "C"`). Each unsafe block states why it holds.
#![allow(unsafe_code)]

/// The ABI version this crate describes. A host loads only plugins of its own version.
pub const ABI_VERSION: u32 = 1;

/// The name of the one exported symbol: a static [`PluginDeclaration`].
pub const DECLARATION_SYMBOL: &str = "ballbar_plugin_declaration";

/// The call succeeded.
pub const STATUS_OK: i32 = 0;
/// The call failed; the message buffer holds why (UTF-8).
pub const STATUS_ERROR: i32 = 1;
/// The plugin panicked inside the call; the message buffer holds the panic message.
pub const STATUS_PANIC: i32 = 2;

/// Flag: `describe` takes a user's machine file (its text) and builds the machine from it.
pub const FLAG_MACHINE_FILE: u32 = 1;

/// A borrowed UTF-8 string: pointer and length, no terminator.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct StrRef {
    /// First byte (may dangle when `len` is 0).
    pub ptr: *const u8,
    /// Length in bytes.
    pub len: usize,
}

impl StrRef {
    /// A reference to a `'static` string (for the declaration).
    pub const fn from_static(s: &'static str) -> StrRef {
        StrRef { ptr: s.as_ptr(), len: s.len() }
    }

    /// A reference to a string that outlives the call it is passed to.
    pub fn borrowed(s: &str) -> StrRef {
        StrRef { ptr: s.as_ptr(), len: s.len() }
    }

    /// The bytes, checked for null and for a length beyond `max_len`.
    ///
    /// # Safety
    /// `ptr` must point to `len` readable bytes that live for `'a`.
    pub unsafe fn bytes<'a>(&self, max_len: usize) -> Result<&'a [u8], &'static str> {
        if self.len == 0 {
            return Ok(&[]);
        }
        if self.ptr.is_null() {
            return Err("null string pointer");
        }
        if self.len > max_len {
            return Err("string longer than allowed");
        }
        // SAFETY: the caller guarantees `len` readable bytes at `ptr` for 'a; null is excluded.
        Ok(unsafe { std::slice::from_raw_parts(self.ptr, self.len) })
    }
}

/// A byte buffer allocated by the plugin (a `Vec<u8>` taken apart), to be freed by the same
/// plugin's [`PluginDeclaration::free_buffer`].
#[repr(C)]
#[derive(Debug)]
pub struct OwnedBuffer {
    /// Start, or null for an empty buffer.
    pub ptr: *mut u8,
    /// Length in bytes.
    pub len: usize,
    /// Capacity (the allocation), needed to free it.
    pub cap: usize,
}

impl OwnedBuffer {
    /// An empty buffer (nothing to free).
    pub const EMPTY: OwnedBuffer = OwnedBuffer { ptr: std::ptr::null_mut(), len: 0, cap: 0 };

    /// Take a string apart into a buffer (plugin side).
    pub fn from_string(s: String) -> OwnedBuffer {
        let mut v = std::mem::ManuallyDrop::new(s.into_bytes());
        OwnedBuffer { ptr: v.as_mut_ptr(), len: v.len(), cap: v.capacity() }
    }
}

/// The state of one joint at one sample, in the model's internal units: mm or rad, mm/s or
/// rad/s, direction of motion (+1, -1, 0), seconds since the run's start, feed in mm/s,
/// seconds since the axis's last reversal (∞ before the first), seconds since the session's
/// start.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RawJointState {
    /// Axis coordinate.
    pub q: f64,
    /// Axis velocity.
    pub velocity: f64,
    /// Direction of motion.
    pub direction: f64,
    /// Time since the run's start, s.
    pub t_s: f64,
    /// Programmed path feed, mm/s.
    pub feed_mm_per_s: f64,
    /// Time since the axis last reversed within the run, s (∞ before its first reversal).
    pub since_reversal_s: f64,
    /// Time since the session's start (the first run's start), s.
    pub session_t_s: f64,
}

/// A named error-term kernel.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct KernelDeclaration {
    /// The name a machine description uses (`TermSpec::Kernel { kernel: "...", .. }`).
    pub name: StrRef,
}

// SAFETY: a declaration points only to 'static immutable strings.
unsafe impl Sync for KernelDeclaration {}

/// `describe(input, out) -> status`: the machine description as RON text into `out` (on
/// [`STATUS_OK`]), or the message (otherwise). `input` is empty, or a machine file's text for a
/// plugin with [`FLAG_MACHINE_FILE`].
pub type DescribeFn = unsafe extern "C" fn(input: StrRef, out: *mut OwnedBuffer) -> i32;

/// `evaluate(kernel, states, n, out, message) -> status`: kernel number `kernel` at `n` joint
/// states into `out` (`6 n` doubles, caller-owned: δx, δy, δz, εx, εy, εz per state, in mm and
/// rad per unit coefficient); on failure the message goes to `message`. The host calls
/// kernels from several threads at once (one batch per call, runs in parallel): a kernel must
/// be a pure function of its inputs or synchronise what it shares.
pub type EvaluateFn = unsafe extern "C" fn(
    kernel: usize,
    states: *const RawJointState,
    n: usize,
    out: *mut f64,
    message: *mut OwnedBuffer,
) -> i32;

/// Free a buffer this plugin allocated.
pub type FreeFn = unsafe extern "C" fn(buffer: OwnedBuffer);

/// The one exported symbol. Field order is part of the ABI: `abi_version` and `struct_size`
/// come first and keep their place in every version.
#[repr(C)]
#[derive(Debug)]
pub struct PluginDeclaration {
    /// [`ABI_VERSION`] of the crate the plugin was built with.
    pub abi_version: u32,
    /// `size_of::<PluginDeclaration>()` as the plugin saw it.
    pub struct_size: u32,
    /// The machine type's name (`column`), UTF-8.
    pub name: StrRef,
    /// The plugin's version (its crate version), UTF-8.
    pub version: StrRef,
    /// [`FLAG_MACHINE_FILE`] or 0.
    pub flags: u32,
    /// The machine description (never null in a valid declaration; `Option` so that a host
    /// can check a foreign library's table instead of trusting it).
    pub describe: Option<DescribeFn>,
    /// Kernel evaluation (never null in a valid declaration).
    pub evaluate: Option<EvaluateFn>,
    /// Frees the plugin's buffers (never null in a valid declaration).
    pub free_buffer: Option<FreeFn>,
    /// Number of kernels.
    pub kernel_count: usize,
    /// The kernels (`kernel_count` of them), or null.
    pub kernels: *const KernelDeclaration,
    /// `size_of::<RawJointState>()` as the plugin saw it: the stride of the state batches.
    pub joint_state_size: u32,
}

// SAFETY: the declaration is immutable and points only to 'static data and functions.
unsafe impl Sync for PluginDeclaration {}

/// The size the host expects in [`PluginDeclaration::joint_state_size`].
pub const JOINT_STATE_SIZE: u32 = std::mem::size_of::<RawJointState>() as u32;

/// The size the host expects in [`PluginDeclaration::struct_size`].
pub const DECLARATION_SIZE: u32 = std::mem::size_of::<PluginDeclaration>() as u32;

/// Plugin-side helpers that [`declare_plugin!`] wires up: each catches panics and moves
/// strings into [`OwnedBuffer`]s.
pub mod export {
    use super::*;
    use std::cell::RefCell;
    use std::panic::{AssertUnwindSafe, catch_unwind};

    /// A plugin's description function: input (empty, or a machine file's text) to RON.
    pub type Describe = fn(&str) -> Result<String, String>;
    /// A plugin's kernel: the basis at each state into `out` (as long as `states`).
    pub type Kernel = fn(&[RawJointState], &mut [[f64; 6]]) -> Result<(), String>;

    thread_local! {
        static LAST_PANIC: RefCell<Option<String>> = const { RefCell::new(None) };
    }

    /// Install (once) a panic hook that records the message and location for the call that
    /// catches it, instead of printing into the host's terminal.
    fn quiet_panics() {
        static ONCE: std::sync::Once = std::sync::Once::new();
        ONCE.call_once(|| {
            std::panic::set_hook(Box::new(|info| {
                let msg = info
                    .payload()
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| info.payload().downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "panic with a non-text payload".to_string());
                let at = info
                    .location()
                    .map(|l| format!(" at {}:{}", l.file(), l.line()))
                    .unwrap_or_default();
                LAST_PANIC.with(|p| *p.borrow_mut() = Some(format!("{msg}{at}")));
            }));
        });
    }

    fn panic_message() -> String {
        LAST_PANIC.with(|p| p.borrow_mut().take()).unwrap_or_else(|| "panic".to_string())
    }

    /// Write `text` to `out` (if not null).
    ///
    /// # Safety
    /// `out` is null or valid for a write of one `OwnedBuffer`.
    unsafe fn put(out: *mut OwnedBuffer, text: String) {
        if !out.is_null() {
            // SAFETY: the caller guarantees `out` is writable.
            unsafe { out.write(OwnedBuffer::from_string(text)) };
        }
    }

    /// The body of a plugin's `describe`.
    ///
    /// # Safety
    /// `input` points to `input.len` readable bytes for the call; `out` is null or writable.
    pub unsafe fn describe(f: Describe, input: StrRef, out: *mut OwnedBuffer) -> i32 {
        quiet_panics();
        // SAFETY: the host passes a string it owns for the duration of the call.
        let bytes = match unsafe { input.bytes(usize::MAX) } {
            Ok(b) => b,
            Err(e) => {
                // SAFETY: as for `out` above.
                unsafe { put(out, e.to_string()) };
                return STATUS_ERROR;
            }
        };
        let Ok(text) = std::str::from_utf8(bytes) else {
            // SAFETY: as above.
            unsafe { put(out, "the input is not UTF-8".to_string()) };
            return STATUS_ERROR;
        };
        let (status, message) = match catch_unwind(AssertUnwindSafe(|| f(text))) {
            Ok(Ok(ron)) => (STATUS_OK, ron),
            Ok(Err(e)) => (STATUS_ERROR, e),
            Err(_) => (STATUS_PANIC, panic_message()),
        };
        // SAFETY: as above.
        unsafe { put(out, message) };
        status
    }

    /// The body of a plugin's `evaluate`.
    ///
    /// # Safety
    /// `states` points to `n` readable states and `out` to `6 n` writable doubles for the
    /// call; `message` is null or writable.
    pub unsafe fn evaluate(
        kernels: &[Kernel],
        kernel: usize,
        states: *const RawJointState,
        n: usize,
        out: *mut f64,
        message: *mut OwnedBuffer,
    ) -> i32 {
        quiet_panics();
        let Some(f) = kernels.get(kernel) else {
            // SAFETY: as for `message` above.
            unsafe {
                put(
                    message,
                    format!("no kernel number {kernel} (the plugin has {})", kernels.len()),
                )
            };
            return STATUS_ERROR;
        };
        if n == 0 {
            return STATUS_OK;
        }
        if states.is_null() || out.is_null() {
            // SAFETY: as above.
            unsafe { put(message, "null state or output buffer".to_string()) };
            return STATUS_ERROR;
        }
        // SAFETY: the host passes `n` states and a buffer of `6 n` doubles (`[f64; 6]` has the
        // alignment of f64 and no padding), both alive and unaliased for the call.
        let (states, out) = unsafe {
            (
                std::slice::from_raw_parts(states, n),
                std::slice::from_raw_parts_mut(out.cast::<[f64; 6]>(), n),
            )
        };
        match catch_unwind(AssertUnwindSafe(|| f(states, out))) {
            Ok(Ok(())) => STATUS_OK,
            Ok(Err(e)) => {
                // SAFETY: as above.
                unsafe { put(message, e) };
                STATUS_ERROR
            }
            Err(_) => {
                // SAFETY: as above.
                unsafe { put(message, panic_message()) };
                STATUS_PANIC
            }
        }
    }

    /// The plugin's `free_buffer`.
    ///
    /// # Safety
    /// `buffer` came from [`OwnedBuffer::from_string`] in this plugin and is freed once.
    pub unsafe extern "C" fn free_buffer(buffer: OwnedBuffer) {
        if buffer.ptr.is_null() {
            return;
        }
        let _ = catch_unwind(AssertUnwindSafe(|| {
            // SAFETY: the parts came from a Vec<u8> of this allocator (from_string).
            drop(unsafe { Vec::from_raw_parts(buffer.ptr, buffer.len, buffer.cap) });
        }));
    }
}

/// Declare a plugin: exports [`DECLARATION_SYMBOL`] with the given name, version, flags,
/// description function ([`export::Describe`]) and kernels ([`export::Kernel`]).
#[macro_export]
macro_rules! declare_plugin {
    (
        name: $name:expr,
        version: $version:expr,
        flags: $flags:expr,
        describe: $describe:path,
        kernels: [$(($kname:expr, $kfn:path)),* $(,)?] $(,)?
    ) => {
        const __BALLBAR_KERNEL_FNS: &[$crate::export::Kernel] = &[$($kfn),*];
        const __BALLBAR_KERNELS: &[$crate::KernelDeclaration] = &[$($crate::KernelDeclaration { name: $crate::StrRef::from_static($kname) }),*];

        #[allow(unsafe_code)]
        unsafe extern "C" fn __ballbar_describe(input: $crate::StrRef, out: *mut $crate::OwnedBuffer) -> i32 {
            // SAFETY: forwarded from the host, which keeps the contract of `DescribeFn`.
            unsafe { $crate::export::describe($describe, input, out) }
        }

        #[allow(unsafe_code)]
        unsafe extern "C" fn __ballbar_evaluate(
            kernel: usize,
            states: *const $crate::RawJointState,
            n: usize,
            out: *mut f64,
            message: *mut $crate::OwnedBuffer,
        ) -> i32 {
            // SAFETY: forwarded from the host, which keeps the contract of `EvaluateFn`.
            unsafe { $crate::export::evaluate(__BALLBAR_KERNEL_FNS, kernel, states, n, out, message) }
        }

        /// The plugin's declaration (the one exported symbol).
        #[allow(unsafe_code)]
        #[unsafe(export_name = "ballbar_plugin_declaration")]
        pub static BALLBAR_PLUGIN_DECLARATION: $crate::PluginDeclaration = $crate::PluginDeclaration {
            abi_version: $crate::ABI_VERSION,
            struct_size: $crate::DECLARATION_SIZE,
            name: $crate::StrRef::from_static($name),
            version: $crate::StrRef::from_static($version),
            flags: $flags,
            describe: Some(__ballbar_describe),
            evaluate: Some(__ballbar_evaluate),
            free_buffer: Some($crate::export::free_buffer),
            kernel_count: __BALLBAR_KERNELS.len(),
            kernels: __BALLBAR_KERNELS.as_ptr(),
            joint_state_size: $crate::JOINT_STATE_SIZE,
        };
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    fn describe(input: &str) -> Result<String, String> {
        match input {
            "" => Ok("(name: \"t\")".into()),
            "panic" => panic!("asked to panic"),
            other => Err(format!("1:1: cannot read {other}")),
        }
    }

    fn double_q(states: &[RawJointState], out: &mut [[f64; 6]]) -> Result<(), String> {
        for (o, s) in out.iter_mut().zip(states) {
            *o = [2.0 * s.q, 0.0, 0.0, 0.0, 0.0, s.velocity];
        }
        Ok(())
    }

    mod declared {
        use super::{describe, double_q};
        crate::declare_plugin! {
            name: "test",
            version: "1.2.3",
            flags: crate::FLAG_MACHINE_FILE,
            describe: describe,
            kernels: [("double_q", double_q)],
        }
    }

    fn call_describe(input: &str) -> (i32, String) {
        let d = &declared::BALLBAR_PLUGIN_DECLARATION;
        let mut out = OwnedBuffer::EMPTY;
        // SAFETY: a declaration made by the macro in this process; the input outlives the call.
        let status = unsafe { (d.describe.unwrap())(StrRef::borrowed(input), &mut out) };
        // SAFETY: the buffer came from the plugin's from_string and is read before it is freed.
        let text = unsafe {
            String::from_utf8_lossy(std::slice::from_raw_parts(out.ptr, out.len)).into_owned()
        };
        // SAFETY: freed once, by the plugin's own function.
        unsafe { (d.free_buffer.unwrap())(out) };
        (status, text)
    }

    #[test]
    fn the_declaration_carries_version_size_name_and_kernels() {
        let d = &declared::BALLBAR_PLUGIN_DECLARATION;
        assert_eq!(d.abi_version, ABI_VERSION);
        assert_eq!(d.struct_size, DECLARATION_SIZE);
        // SAFETY: static strings of the declaration.
        assert_eq!(unsafe { d.name.bytes(64) }.unwrap(), b"test");
        assert_eq!(unsafe { d.version.bytes(64) }.unwrap(), b"1.2.3");
        assert_eq!(d.kernel_count, 1);
        assert_eq!(d.joint_state_size, JOINT_STATE_SIZE);
        // SAFETY: one kernel declaration at `kernels`.
        assert_eq!(unsafe { (*d.kernels).name.bytes(64) }.unwrap(), b"double_q");
    }

    #[test]
    fn describe_returns_text_errors_and_caught_panics() {
        assert_eq!(call_describe(""), (STATUS_OK, "(name: \"t\")".to_string()));
        assert_eq!(call_describe("x"), (STATUS_ERROR, "1:1: cannot read x".to_string()));
        let (status, msg) = call_describe("panic");
        assert_eq!(status, STATUS_PANIC);
        assert!(msg.starts_with("asked to panic at "), "{msg}");
    }

    #[test]
    fn kernels_evaluate_into_the_callers_buffer_and_bad_numbers_are_errors() {
        let d = &declared::BALLBAR_PLUGIN_DECLARATION;
        let states = [
            RawJointState { q: 1.5, velocity: -2.0, ..Default::default() },
            RawJointState { q: -3.0, ..Default::default() },
        ];
        let mut out = [0.0; 12];
        let mut msg = OwnedBuffer::EMPTY;
        // SAFETY: two states, twelve doubles, all alive for the call.
        let status =
            unsafe { (d.evaluate.unwrap())(0, states.as_ptr(), 2, out.as_mut_ptr(), &mut msg) };
        assert_eq!(status, STATUS_OK);
        assert_eq!(out, [3.0, 0.0, 0.0, 0.0, 0.0, -2.0, -6.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        // SAFETY: as above; kernel 7 does not exist.
        let status =
            unsafe { (d.evaluate.unwrap())(7, states.as_ptr(), 2, out.as_mut_ptr(), &mut msg) };
        assert_eq!(status, STATUS_ERROR);
        // SAFETY: freed once, by the plugin's own function.
        unsafe { (d.free_buffer.unwrap())(msg) };
    }
}
