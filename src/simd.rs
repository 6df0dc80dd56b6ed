//! Run a loop with the widest vector instructions the processor has, chosen at run time.
//!
//! lidarsim is built for the baseline of its target (x86-64: SSE2, two f64 an instruction) so
//! that one binary runs on every machine, and it forbids `unsafe`. Its hot loops are written
//! branch-free over small arrays (per-channel lanes, a line's wing over a cluster of
//! wavenumbers) so that the compiler vectorises them; [`dispatch`] compiles such a loop a
//! second time with AVX2 (four f64 an instruction) and picks the copy the processor can run,
//! through `pulp`, which does the detection and the `unsafe` call behind a safe interface.
//!
//! The numbers do not change: the same IEEE operations run in the same order, only more of them
//! at once (Rust never fuses a multiply and an add into an FMA on its own), so a result is the
//! same bit for bit on every processor.

use std::sync::OnceLock;

pub(crate) use pulp::{Simd, WithSimd};

/// The instruction set detected once per process.
fn arch() -> pulp::Arch {
    static ARCH: OnceLock<pulp::Arch> = OnceLock::new();
    *ARCH.get_or_init(pulp::Arch::new)
}

/// `op` compiled for the best instruction set of this processor. Everything `op` does must be
/// inlined into it (`#[inline(always)]` on its `with_simd` and on the functions that calls) for
/// the wider instructions to reach it. Hence a small struct implementing [`WithSimd`] at each
/// call, not a closure (which pulp also takes): the closure's body is not inlined into the
/// dispatched copy, and a study ran 1.27× slower that way (2.53–2.60 s of CPU against
/// 1.95–2.03 s, `bench --study 60`, 1 thread).
#[inline(always)]
pub(crate) fn dispatch<Op: WithSimd>(op: Op) -> Op::Output {
    arch().dispatch(op)
}

/// Channels from which a per-channel kernel ([`wide_fn!`]) takes the dispatched copy: with fewer
/// the AVX2 loop would run no full vector of four, and the call through the dispatch costs more
/// than SSE2's two lanes lose.
pub(crate) const WIDE_FROM: usize = 8;

/// A function whose body is compiled twice, for the baseline and (through [`dispatch`]) for
/// the best instruction set of the processor, the copy chosen at each call by a condition
/// (`where wide(cond)`, on the arguments): for the per-channel kernels of the Monte Carlo, the
/// baseline's SSE2 pass below [`WIDE_FROM`] channels (C.1's one-channel walk keeps its code),
/// the AVX2 copy from there on. The body is an `#[inline(always)]` function of the same
/// arguments, wrapped in a [`WithSimd`] struct, so that all of it reaches the wider copy.
/// Each argument's type names the one lifetime parameter.
macro_rules! wide_fn {
    (
        $(#[$attr:meta])*
        $vis:vis fn $name:ident<$lt:lifetime>($($arg:ident : $ty:ty),* $(,)?) $(-> $out:ty)?
        where wide($cond:expr)
        $body:block
    ) => {
        $(#[$attr])*
        #[inline]
        $vis fn $name<$lt>($($arg: $ty),*) $(-> $out)? {
            #[inline(always)]
            #[allow(clippy::too_many_arguments)]
            fn body<$lt>($($arg: $ty),*) $(-> $out)? $body
            struct Op<$lt> {
                $($arg: $ty),*
            }
            impl<$lt> $crate::simd::WithSimd for Op<$lt> {
                type Output = $crate::simd::wide_fn!(@out $($out)?);
                #[inline(always)]
                fn with_simd<S: $crate::simd::Simd>(self, _: S) -> Self::Output {
                    let Op { $($arg),* } = self;
                    body($($arg),*)
                }
            }
            if $cond {
                $crate::simd::dispatch(Op { $($arg),* })
            } else {
                body($($arg),*)
            }
        }
    };
    (@out) => { () };
    (@out $t:ty) => { $t };
}
pub(crate) use wide_fn;
