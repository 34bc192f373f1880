//! Kernels compiled for the widest vectors the processor has: `wide_vectors!` defines a
//! function that runs an `#[inline(always)]` kernel compiled with AVX-512F or AVX where the
//! processor supports them (checked at run time), else as compiled for the target. The
//! kernel's operations and their order per result are the same in every build (Rust does not
//! contract `a * b + c` into fused multiply-adds), so the results are bitwise equal.

/// `wide_vectors! { fn name[generics](args) => kernel[generic arguments], avx512 = name_a,
/// avx = name_b { body } }` defines the kernel `fn kernel(args) { body }` (inlined into its
/// callers), and `fn name` (returning `()`), which runs it through `unsafe fn name_a` (compiled
/// with AVX-512F) or `unsafe fn name_b` (with AVX) where the processor has them, and directly
/// otherwise.
macro_rules! wide_vectors {
    (
        $(#[$doc:meta])*
        fn $name:ident $([$($gen:tt)*])? ($($arg:ident: $ty:ty),* $(,)?)
            => $kernel:ident $([$($garg:tt)*])?, avx512 = $avx512:ident, avx = $avx:ident
            $body:block
    ) => {
        $(#[$doc])*
        fn $name $(<$($gen)*>)? ($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: the processor supports AVX-512F, the only requirement.
                    unsafe { $avx512 $(::<$($garg)*>)? ($($arg),*) };
                    return;
                }
                if std::arch::is_x86_feature_detected!("avx") {
                    // SAFETY: the processor supports AVX, the only requirement.
                    unsafe { $avx $(::<$($garg)*>)? ($($arg),*) };
                    return;
                }
            }
            $kernel $(::<$($garg)*>)? ($($arg),*)
        }

        #[doc = concat!("The kernel of [`", stringify!($name), "`], in the target's baseline build.")]
        #[inline(always)]
        fn $kernel $(<$($gen)*>)? ($($arg: $ty),*) $body

        #[doc = concat!("[`", stringify!($kernel), "`] compiled with AVX-512F enabled.")]
        ///
        /// # Safety
        /// The processor must support AVX-512F.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f")]
        unsafe fn $avx512 $(<$($gen)*>)? ($($arg: $ty),*) {
            $kernel $(::<$($garg)*>)? ($($arg),*)
        }

        #[doc = concat!("[`", stringify!($kernel), "`] compiled with AVX enabled.")]
        ///
        /// # Safety
        /// The processor must support AVX.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx")]
        unsafe fn $avx $(<$($gen)*>)? ($($arg: $ty),*) {
            $kernel $(::<$($garg)*>)? ($($arg),*)
        }
    };
}
