//! The page allocator of one commit (format §11.3): first-fit runs of free pages that no
//! snapshot and no durable state can reach, else pages appended past the end.
//!
//! A free page freed by txn `F` may still be reached by states older than `F`. The commit
//! passes the reuse limit `L = min(base txn, oldest snapshot's txn)`: only pages with
//! `freed_txn <= L` are handed out or cut from the end.

use std::collections::BTreeMap;

/// Free pages and the end of the file, for one commit.
pub(crate) struct Alloc {
    /// Free pages and the txn that freed them.
    pub pool: BTreeMap<u64, u64>,
    /// Pages freed up to this txn id can be reused now.
    pub reuse_limit: u64,
    /// First page past the end.
    pub end: u64,
    /// Pages handed out from the pool.
    pub reused: u64,
    /// Pages appended past the base's end.
    pub appended: u64,
}

impl Alloc {
    /// An allocator over `pool` for a file of `end` pages.
    pub fn new(pool: BTreeMap<u64, u64>, reuse_limit: u64, end: u64) -> Alloc {
        Alloc {
            pool,
            reuse_limit,
            end,
            reused: 0,
            appended: 0,
        }
    }

    /// `n` consecutive pages: the first reusable run in the pool, else appended.
    pub fn extent(&mut self, n: u64) -> u64 {
        match self.reusable_run(n) {
            Some(first) => self.take(first, n),
            None => self.append(n),
        }
    }

    /// Takes the run `first .. first + n` out of the pool.
    pub fn take(&mut self, first: u64, n: u64) -> u64 {
        for p in first..first + n {
            self.pool.remove(&p);
        }
        self.reused += n;
        first
    }

    /// `n` pages past the end.
    pub fn append(&mut self, n: u64) -> u64 {
        let first = self.end;
        self.end += n;
        self.appended += n;
        first
    }

    /// The first run of `n` consecutive reusable pages in the pool (first fit, lowest
    /// pages first: what is written gathers at the front of the file, and free pages at its
    /// end, where a later commit cuts them off; best fit, tried first, left holes all through
    /// an edited file and kept its length).
    pub fn reusable_run(&self, n: u64) -> Option<u64> {
        self.best_run(n).map(|(first, _)| first)
    }

    /// The run [`Alloc::reusable_run`] picks, with its whole length: `(first, length)`.
    pub fn best_run(&self, n: u64) -> Option<(u64, u64)> {
        let (mut start, mut len) = (0u64, 0u64);
        for (&p, &freed) in &self.pool {
            if freed > self.reuse_limit {
                if len >= n.max(1) {
                    return Some((start, len));
                }
                len = 0;
                continue;
            }
            if len > 0 && p == start + len {
                len += 1;
            } else {
                if len >= n.max(1) {
                    return Some((start, len));
                }
                start = p;
                len = 1;
            }
        }
        (len >= n.max(1)).then_some((start, len))
    }

    /// The reusable free pages: how many, and the longest run of them.
    pub fn holes(&self) -> (u64, u64) {
        let reusable: Vec<u64> = self
            .pool
            .iter()
            .filter(|&(_, &freed)| freed <= self.reuse_limit)
            .map(|(&page, _)| page)
            .collect();
        let longest = reusable
            .chunk_by(|a, b| a + 1 == *b)
            .map(|run| run.len() as u64)
            .max()
            .unwrap_or(0);
        (reusable.len() as u64, longest)
    }

    /// Whether `page` is a free page this commit may write.
    pub fn reusable(&self, page: u64) -> bool {
        self.pool
            .get(&page)
            .is_some_and(|&freed| freed <= self.reuse_limit)
    }

    /// Takes the run `first .. first + n` out of the pool, as [`Alloc::take`] does, and
    /// returns the txn that freed each page (for [`Alloc::give_back`]).
    pub fn take_freed(&mut self, first: u64, n: u64) -> Vec<Option<u64>> {
        let freed = (first..first + n)
            .map(|page| self.pool.get(&page).copied())
            .collect();
        self.take(first, n);
        freed
    }

    /// Gives back a page [`Alloc::take`] handed out and the commit did not write, freed as
    /// before by `freed_txn`.
    pub fn give_back(&mut self, page: u64, freed_txn: u64) {
        self.pool.insert(page, freed_txn);
        self.reused -= 1;
    }

    /// Gives back a page [`Alloc::append`] handed out and the commit did not write: the end
    /// moves back over it when it is the last page, else it joins the pool as reusable now
    /// (past the base's end, no state reaches it).
    pub fn give_back_appended(&mut self, page: u64) {
        self.appended -= 1;
        if page + 1 == self.end {
            self.end -= 1;
        } else {
            self.pool.insert(page, self.reuse_limit);
        }
    }

    /// Frees `page` as of txn `txn`.
    pub fn free(&mut self, page: u64, txn: u64) {
        self.pool.insert(page, txn);
    }

    /// Drops reusable free pages at the end of the file, never below `floor` pages.
    pub fn trim(&mut self, floor: u64) {
        while self.end > floor.max(2) {
            match self.pool.get(&(self.end - 1)) {
                Some(&freed) if freed <= self.reuse_limit => {
                    self.pool.remove(&(self.end - 1));
                    self.end -= 1;
                }
                _ => break,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_respect_the_reuse_limit_and_the_end_is_trimmed() {
        // Pages 5, 6 freed by txn 3; 7 by txn 9; 9, 10 by txn 2; the file has 11 pages.
        let pool = [(5, 3), (6, 3), (7, 9), (9, 2), (10, 2)]
            .into_iter()
            .collect();
        let mut a = Alloc::new(pool, 4, 11);
        assert_eq!(a.holes(), (4, 2), "5, 6, 9, 10 reusable; 7 is not yet");
        assert_eq!(a.reusable_run(3), None, "page 7 is not reusable yet");
        assert_eq!(a.extent(2), 5);
        assert_eq!(a.extent(3), 11, "appended");
        a.trim(0);
        assert_eq!(a.end, 14, "the appended pages end the file");
        let mut b = Alloc::new([(9, 2), (10, 2)].into_iter().collect(), 2, 11);
        b.trim(0);
        assert_eq!(b.end, 9);
        // A floor (a dataset's pinned state's length) keeps the free pages above it.
        let mut c = Alloc::new([(9, 2), (10, 2)].into_iter().collect(), 2, 11);
        c.trim(10);
        assert_eq!(c.end, 10);
        assert!(c.pool.contains_key(&9) && !c.pool.contains_key(&10));
    }

    #[test]
    fn the_first_run_that_holds_an_extent_is_taken() {
        // Runs 3..=7 (five pages) and 20..=21 (two): first fit takes from the lowest run
        // that holds the extent, so written pages gather at the front of the file.
        let pool = (3..=7).chain(20..=21).map(|p| (p, 1)).collect();
        let mut a = Alloc::new(pool, 1, 30);
        assert_eq!(a.best_run(2), Some((3, 5)));
        assert_eq!(a.extent(2), 3);
        assert_eq!(a.extent(3), 5);
        assert_eq!(a.extent(2), 20);
        assert_eq!(a.extent(1), 30, "nothing left to reuse");
    }
}
