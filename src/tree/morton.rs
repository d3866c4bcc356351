//! The points' Morton order: a parallel, stable radix sort of 63-bit codes.

use glam::Vec3;

use super::{par_chunks, CHUNK};

/// The points' order by 63-bit Morton code of their position quantised to
/// 2^21 steps over the bounding cube; equal codes keep input order (a
/// stable LSD radix sort, so the order is unique).
pub fn morton_order(positions: &[Vec3], threads: usize) -> Vec<u32> {
    morton_order_in(positions, threads, None)
}

/// [`morton_order`] over a cube twice the size, moved by `shift` (in
/// units of the bounding cube's side, each in [0, 1)): another order whose
/// cell boundaries fall elsewhere.
fn morton_order_in(positions: &[Vec3], threads: usize, shift: Option<Vec3>) -> Vec<u32> {
    radix_sort(morton_keys(positions, threads, shift), threads)
}

/// The 63-bit codes [`morton_order_in`] sorts.
pub(super) fn morton_keys(positions: &[Vec3], threads: usize, shift: Option<Vec3>) -> Vec<u64> {
    let (lo, hi) = positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let mut extent = (hi - lo).max_element().max(f32::MIN_POSITIVE);
    let mut origin = lo;
    if let Some(shift) = shift {
        origin -= shift * extent;
        extent *= 2.0;
    }
    let scale = ((1u32 << 21) - 1) as f32 / extent;
    let mut keys = vec![0u64; positions.len()];
    par_chunks(&mut keys, CHUNK, threads, |c, out| {
        for (j, k) in out.iter_mut().enumerate() {
            let q = ((positions[c * CHUNK + j] - origin) * scale)
                .round()
                .clamp(Vec3::ZERO, Vec3::splat(((1u32 << 21) - 1) as f32))
                .as_uvec3();
            *k = spread3(q.x) | spread3(q.y) << 1 | spread3(q.z) << 2;
        }
    });
    keys
}

/// The low 21 bits of `v`, two zero bits after each.
fn spread3(v: u32) -> u64 {
    let mut x = (v & 0x1F_FFFF) as u64;
    x = (x | x << 32) & 0x1F_0000_0000_FFFF;
    x = (x | x << 16) & 0x1F_0000_FF00_00FF;
    x = (x | x << 8) & 0x100F_00F0_0F00_F00F;
    x = (x | x << 4) & 0x10C3_0C30_C30C_30C3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// The stable order of `keys` (LSD radix sort, 8 bits a pass, passes where
/// every key has the same digit skipped), on `threads` threads: each pass
/// counts digits per chunk in parallel, then scatters each chunk to its
/// own offsets, so the result is the same for any split. The arrays are
/// atomics (relaxed: plain loads and stores on x86) so that the threads
/// may write to disjoint, scattered indices without `unsafe`.
pub(super) fn radix_sort(keys: Vec<u64>, threads: usize) -> Vec<u32> {
    use std::sync::atomic::{AtomicU32, AtomicU64, Ordering::Relaxed};
    let n = keys.len();
    let mut keys: Vec<AtomicU64> = keys.into_iter().map(AtomicU64::new).collect();
    let mut index: Vec<AtomicU32> = (0..n as u32).map(AtomicU32::new).collect();
    let mut keys_out: Vec<AtomicU64> = (0..n).map(|_| AtomicU64::new(0)).collect();
    let mut index_out: Vec<AtomicU32> = (0..n).map(|_| AtomicU32::new(0)).collect();
    let chunk = n.div_ceil(threads.max(1)).max(CHUNK);
    for pass in 0..8 {
        let shift = pass * 8;
        let digit = |k: &AtomicU64| (k.load(Relaxed) >> shift) as usize & 0xFF;
        let counts: Vec<[usize; 256]> = std::thread::scope(|scope| {
            let handles: Vec<_> = keys
                .chunks(chunk)
                .map(|part| {
                    scope.spawn(move || {
                        let mut c = [0usize; 256];
                        part.iter().for_each(|k| c[digit(k)] += 1);
                        c
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("a counting thread does not panic"))
                .collect()
        });
        if (0..256).any(|d| counts.iter().map(|c| c[d]).sum::<usize>() == n) {
            continue; // Every key has the same digit: the order stands.
        }
        // Offsets: digit-major, then chunk order (stability).
        let mut offsets = vec![[0usize; 256]; counts.len()];
        let mut at = 0usize;
        for d in 0..256 {
            for (o, c) in offsets.iter_mut().zip(&counts) {
                o[d] = at;
                at += c[d];
            }
        }
        std::thread::scope(|scope| {
            for ((part, idx), mut off) in keys.chunks(chunk).zip(index.chunks(chunk)).zip(offsets) {
                let (keys_out, index_out) = (&keys_out, &index_out);
                scope.spawn(move || {
                    for (k, i) in part.iter().zip(idx) {
                        let d = digit(k);
                        keys_out[off[d]].store(k.load(Relaxed), Relaxed);
                        index_out[off[d]].store(i.load(Relaxed), Relaxed);
                        off[d] += 1;
                    }
                });
            }
        });
        std::mem::swap(&mut keys, &mut keys_out);
        std::mem::swap(&mut index, &mut index_out);
    }
    index.into_iter().map(AtomicU32::into_inner).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_order_is_a_stable_sort_by_code() {
        let mut positions: Vec<Vec3> = (0..5000)
            .map(|i| {
                Vec3::new(
                    (i * 7919 % 100) as f32,
                    (i * 104729 % 37) as f32,
                    (i % 11) as f32,
                )
            })
            .collect();
        positions.push(positions[3]); // a duplicate: input order kept
        for threads in [1, 2, 3] {
            let order = morton_order(&positions, threads);
            let mut sorted: Vec<u32> = (0..positions.len() as u32).collect();
            let code = |p: Vec3| {
                let q = (p / 99.0 * ((1u32 << 21) - 1) as f32).round().as_uvec3();
                spread3(q.x) | spread3(q.y) << 1 | spread3(q.z) << 2
            };
            sorted.sort_by_key(|&i| (code(positions[i as usize]), i));
            assert_eq!(order, sorted, "threads {threads}");
        }
    }

    #[test]
    fn spread3_interleaves() {
        assert_eq!(spread3(0b1011), 0b1_000_001_001);
        assert_eq!(spread3(0x1F_FFFF).count_ones(), 21);
        assert_eq!(spread3(0x1F_FFFF) >> 60, 1);
    }
}
