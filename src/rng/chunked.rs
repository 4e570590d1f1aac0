//! The buffered word stream of a counter-addressed block generator (ChaCha8's
//! [`super::stream::WordStream`], AES-128-CTR's [`super::aes::AesStream`]): words served from
//! one chunk of [`CHUNK`] 64-bit words that the generator's block function makes at a block
//! number; positions in 32-bit words, as [`RngPosition`] counts them.

use super::RngPosition;

/// 64-bit words in a chunk.
pub const CHUNK: usize = 128;

/// A block function: the words of consecutive blocks, addressed by block number.
pub trait BlockFn {
    /// 64-bit words in a block (a divisor of [`CHUNK`]).
    const WORDS: usize;
    /// One chunk (`out.len() == CHUNK`) from blocks `first`, `first + 1`, ...
    fn chunk(&self, first: u128, out: &mut [u64]);
}

/// The stream of a block function and seed: words served from a chunk, whole chunks of a
/// [`fill`](Self::fill) made straight into the caller's slice.
pub struct Chunked<B> {
    seed: u64,
    blocks: B,
    /// Block number of the next chunk to make.
    next_block: u128,
    buf: Box<[u64; CHUNK]>,
    /// Next unread word of `buf` (CHUNK: empty).
    idx: usize,
}

impl<B: BlockFn> Chunked<B> {
    const CHUNK_BLOCKS: u128 = (CHUNK / B::WORDS) as u128;
    /// 32-bit words in a block.
    const BLOCK_WORDS32: u128 = 2 * B::WORDS as u128;

    /// The stream of `blocks` (the seed's generator) at a saved position.
    pub fn new(pos: &RngPosition, blocks: B) -> Self {
        const { assert!(B::WORDS > 0 && CHUNK.is_multiple_of(B::WORDS)) };
        // Position in 32-bit words (always even: the streams serve 64-bit words).
        let p = pos.filled_at + 2 * pos.idx as u128;
        let mut s = Chunked {
            seed: pos.seed,
            blocks,
            next_block: p / Self::BLOCK_WORDS32,
            buf: Box::new([0; CHUNK]),
            idx: CHUNK,
        };
        let skip = ((p % Self::BLOCK_WORDS32) / 2) as usize;
        if skip > 0 {
            s.refill();
            s.idx = skip;
        }
        s
    }

    /// The position (a stream restored from it continues with the same words).
    pub fn position(&self) -> RngPosition {
        RngPosition {
            seed: self.seed,
            filled_at: self.next_block * Self::BLOCK_WORDS32 - 2 * (CHUNK - self.idx) as u128,
            idx: 0,
        }
    }

    fn refill(&mut self) {
        self.blocks.chunk(self.next_block, &mut self.buf[..]);
        self.next_block = self.next_block.wrapping_add(Self::CHUNK_BLOCKS);
        self.idx = 0;
    }

    #[inline(always)]
    pub fn u64(&mut self) -> u64 {
        if self.idx == CHUNK {
            self.refill();
        }
        let w = self.buf[self.idx];
        self.idx += 1;
        w
    }

    /// Uniform in [0, 1) with 53 random bits.
    #[inline(always)]
    pub fn f64(&mut self) -> f64 {
        super::unit_f64(self.u64())
    }

    /// Uniform in (0, 1].
    #[inline(always)]
    pub fn f64_open0(&mut self) -> f64 {
        super::unit_f64_open0(self.u64())
    }

    /// The next `out.len()` words.
    pub fn fill(&mut self, out: &mut [u64]) {
        let take = (CHUNK - self.idx).min(out.len());
        out[..take].copy_from_slice(&self.buf[self.idx..self.idx + take]);
        self.idx += take;
        let mut rest = &mut out[take..];
        while rest.len() >= CHUNK {
            let (head, tail) = rest.split_at_mut(CHUNK);
            self.blocks.chunk(self.next_block, head);
            self.next_block = self.next_block.wrapping_add(Self::CHUNK_BLOCKS);
            rest = tail;
        }
        if !rest.is_empty() {
            self.refill();
            let k = rest.len();
            rest.copy_from_slice(&self.buf[..k]);
            self.idx = k;
        }
    }
}
