//! Large particle arrays backed by transparent huge pages where the kernel allows it.
//!
//! DSMC touches two random particles per trial: with 4 KiB pages almost every access is a TLB
//! miss on a 38 MB array (a two-level page walk in a VM). `madvise(MADV_HUGEPAGE)` before the
//! pages are first touched lets the kernel back the array with 2 MiB pages.

/// A vector of `n` copies of `fill`, advised for huge pages before it is first written.
pub fn huge_vec<T: Copy>(n: usize, fill: T) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(n);
    advise_huge(v.as_mut_ptr() as *mut u8, n * std::mem::size_of::<T>());
    v.resize(n, fill);
    v
}

/// A copy of `src` in huge-page-advised memory.
pub fn huge_copy<T: Copy>(src: &[T]) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(src.len());
    advise_huge(v.as_mut_ptr() as *mut u8, std::mem::size_of_val(src));
    v.extend_from_slice(src);
    v
}

fn advise_huge(ptr: *mut u8, bytes: usize) {
    const HUGE: usize = 2 << 20;
    if bytes < 2 * HUGE {
        return;
    }
    #[cfg(target_os = "linux")]
    {
        let start = (ptr as usize).div_ceil(HUGE) * HUGE;
        let end = (ptr as usize + bytes) / HUGE * HUGE;
        if end > start {
            // SAFETY: the range lies inside an allocation we own; madvise only sets a hint.
            unsafe {
                libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (ptr, bytes);
}
