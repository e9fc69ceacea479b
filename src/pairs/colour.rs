//! Colouring of the pair rows: no two rows of a colour share a marble.

use super::*;

impl PairSolver {
    /// Orders the pair rows for the passes by colour (greedy: each row takes the first
    /// colour neither of its marbles has yet; beyond 31 they share the last): consecutive
    /// rows then rarely share a marble, so that one row's update does not wait on the one
    /// before it.
    // Out of line: see `PairSolver::run_passes`.
    #[inline(never)]
    pub(super) fn colour_rows(&mut self) {
        const LAST: u32 = COLOURS as u32 - 1;
        self.colours.clear();
        self.colours.resize(self.bodies.len(), 0);
        let mut count = [0u32; LAST as usize + 2];
        self.pair_slot.clear();
        for r in &self.pair_gs {
            let used = self.colours[r.i as usize] | self.colours[r.j as usize];
            let c = (!used).trailing_zeros().min(LAST);
            self.colours[r.i as usize] |= 1 << c;
            self.colours[r.j as usize] |= 1 << c;
            count[c as usize + 1] += 1;
            self.pair_slot.push(c);
        }
        for c in 1..count.len() {
            count[c] += count[c - 1];
        }
        let starts = count;
        // Scatter by colour (stable), remembering each row's index.
        self.pair_pass.clear();
        self.pair_pass.resize(
            self.pair_gs.len(),
            PairGs {
                i: 0,
                j: 0,
                n: Vec3::ZERO,
                k: 0.0,
                lambda: 0.0,
                target: 0.0,
            },
        );
        for (k, r) in self.pair_gs.iter().enumerate() {
            let c = self.pair_slot[k] as usize;
            let slot = count[c] as usize;
            count[c] += 1;
            self.pair_pass[slot] = *r;
            self.pair_slot[k] = slot as u32;
        }
        // Each colour's rows by four, the rest one by one; the last colour's rows may
        // share marbles, so they all go one by one.
        self.spans.clear();
        self.blocks.clear();
        self.block_first.clear();
        for c in 0..COLOURS {
            let (start, end) = (starts[c], starts[c + 1]);
            if start == end {
                continue;
            }
            let wide_end = if c < LAST as usize {
                start + (end - start) / 4 * 4
            } else {
                start
            };
            let first_block = self.blocks.len() as u32;
            for first in (start..wide_end).step_by(4) {
                let f = first as usize;
                let rows: &[PairGs; 4] = self.pair_pass[f..f + 4].try_into().expect("four rows");
                self.blocks.push(RowBlock::new(rows));
                self.block_first.push(first);
            }
            self.spans.push(ColourSpan {
                blocks: (first_block, self.blocks.len() as u32),
                tail: (wide_end, end),
            });
        }
    }
}
