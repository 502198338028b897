//! The built-in bitmap font: one 5 × 9 glyph per printable ASCII character (32 to 126).
//!
//! Rows 0 to 6 stand above the baseline (capitals and digits are 7 rows tall, lower case letters
//! 5), rows 7 and 8 hold descenders. Letters and punctuation are spaced proportionally (each
//! glyph is as wide as its ink); digits keep the full 5 columns so that numbers line up.

use std::sync::OnceLock;

/// Columns of a glyph cell.
pub(crate) const CELL_W: usize = 5;
/// Rows of a glyph cell, descender included.
pub(crate) const CELL_H: usize = 9;
/// Columns left blank between two glyphs.
pub(crate) const SPACING: usize = 1;
/// Width of the space character, in columns.
const SPACE_W: usize = 3;

/// The glyphs in ASCII order, 16 to a band. Each band is a header line naming its characters
/// followed by the 9 rows of its glyphs, each glyph 5 columns wide and 2 blank columns apart.
const ART: &str = r##"
       !      "      #      $      %      &      '      (      )      *      +      ,      -      .      /
.....  ..#..  .#.#.  .#.#.  ..#..  ##...  .##..  ..#..  ...#.  .#...  .....  .....  .....  .....  .....  ....#
.....  ..#..  .#.#.  .#.#.  .####  ##..#  #..#.  ..#..  ..#..  ..#..  ..#..  ..#..  .....  .....  .....  ...#.
.....  ..#..  .#.#.  #####  #.#..  ...#.  #.#..  ..#..  .#...  ...#.  #.#.#  ..#..  .....  .....  .....  ...#.
.....  ..#..  .....  .#.#.  .###.  ..#..  .#...  .....  .#...  ...#.  .###.  #####  .....  ####.  .....  ..#..
.....  ..#..  .....  #####  ..#.#  .#...  #.#.#  .....  .#...  ...#.  #.#.#  ..#..  .....  .....  .....  .#...
.....  .....  .....  .#.#.  ####.  #..##  #..#.  .....  ..#..  ..#..  ..#..  ..#..  .....  .....  .....  .#...
.....  ..#..  .....  .#.#.  ..#..  ...##  .##.#  .....  ...#.  .#...  .....  .....  ..#..  .....  ..#..  #....
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .#...  .....  .....  .....
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....
0      1      2      3      4      5      6      7      8      9      :      ;      <      =      >      ?
.###.  ..#..  .###.  .###.  ...#.  #####  ..##.  #####  .###.  .###.  .....  .....  ...#.  .....  .#...  .###.
#...#  .##..  #...#  #...#  ..##.  #....  .#...  ....#  #...#  #...#  .....  .....  ..#..  .....  ..#..  #...#
#...#  ..#..  ....#  ....#  .#.#.  ####.  #....  ...#.  #...#  #...#  ..#..  ..#..  .#...  #####  ...#.  ....#
#...#  ..#..  ...#.  ..##.  #..#.  ....#  ####.  ..#..  .###.  .####  .....  .....  #....  .....  ....#  ...#.
#...#  ..#..  ..#..  ....#  #####  ....#  #...#  .#...  #...#  ....#  .....  .....  .#...  #####  ...#.  ..#..
#...#  ..#..  .#...  #...#  ...#.  #...#  #...#  .#...  #...#  ...#.  .....  .....  ..#..  .....  ..#..  .....
.###.  .###.  #####  .###.  ...#.  .###.  .###.  .#...  .###.  .##..  ..#..  ..#..  ...#.  .....  .#...  ..#..
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .#...  .....  .....  .....  .....
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....
@      A      B      C      D      E      F      G      H      I      J      K      L      M      N      O
.###.  .###.  ####.  .###.  ####.  #####  #####  .###.  #...#  .###.  ..###  #...#  #....  #...#  #...#  .###.
#...#  #...#  #...#  #...#  #...#  #....  #....  #...#  #...#  ..#..  ...#.  #..#.  #....  ##.##  #...#  #...#
#.###  #...#  #...#  #....  #...#  #....  #....  #....  #...#  ..#..  ...#.  #.#..  #....  #.#.#  ##..#  #...#
#.#.#  #####  ####.  #....  #...#  ####.  ####.  #.###  #####  ..#..  ...#.  ##...  #....  #.#.#  #.#.#  #...#
#.##.  #...#  #...#  #....  #...#  #....  #....  #...#  #...#  ..#..  ...#.  #.#..  #....  #...#  #..##  #...#
#....  #...#  #...#  #...#  #...#  #....  #....  #...#  #...#  ..#..  #..#.  #..#.  #....  #...#  #...#  #...#
.####  #...#  ####.  .###.  ####.  #####  #....  .####  #...#  .###.  .##..  #...#  #####  #...#  #...#  .###.
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....
P      Q      R      S      T      U      V      W      X      Y      Z      [      \      ]      ^      _
####.  .###.  ####.  .####  #####  #...#  #...#  #...#  #...#  #...#  #####  .###.  #....  .###.  ..#..  .....
#...#  #...#  #...#  #....  ..#..  #...#  #...#  #...#  #...#  #...#  ....#  .#...  .#...  ...#.  .#.#.  .....
#...#  #...#  #...#  #....  ..#..  #...#  #...#  #...#  .#.#.  .#.#.  ...#.  .#...  .#...  ...#.  #...#  .....
####.  #...#  ####.  .###.  ..#..  #...#  #...#  #.#.#  ..#..  ..#..  ..#..  .#...  ..#..  ...#.  .....  .....
#....  #.#.#  #.#..  ....#  ..#..  #...#  #...#  #.#.#  .#.#.  ..#..  .#...  .#...  ...#.  ...#.  .....  .....
#....  #..#.  #..#.  ....#  ..#..  #...#  .#.#.  #.#.#  #...#  ..#..  #....  .#...  ...#.  ...#.  .....  .....
#....  .##.#  #...#  ####.  ..#..  .###.  ..#..  .#.#.  #...#  ..#..  #####  .###.  ....#  .###.  .....  .....
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  #####
.....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....  .....
`      a      b      c      d      e      f      g      h      i      j      k      l      m      n      o
.#...  .....  #....  .....  ....#  .....  ..##.  .....  #....  ..#..  ...#.  #....  .##..  .....  .....  .....
..#..  .....  #....  .....  ....#  .....  .#...  .....  #....  .....  .....  #....  ..#..  .....  .....  .....
.....  .###.  #.##.  .###.  .##.#  .###.  .#...  .####  #.##.  .##..  ..##.  #..#.  ..#..  ##.#.  #.##.  .###.
.....  ....#  ##..#  #....  #..##  #...#  ###..  #...#  ##..#  ..#..  ...#.  #.#..  ..#..  #.#.#  ##..#  #...#
.....  .####  #...#  #....  #...#  #####  .#...  #...#  #...#  ..#..  ...#.  ##...  ..#..  #.#.#  #...#  #...#
.....  #...#  #...#  #...#  #...#  #....  .#...  #...#  #...#  ..#..  ...#.  #.#..  ..#..  #.#.#  #...#  #...#
.....  .####  ####.  .###.  .####  .###.  .#...  .####  #...#  .###.  ...#.  #..#.  .###.  #.#.#  #...#  .###.
.....  .....  .....  .....  .....  .....  .....  ....#  .....  .....  #..#.  .....  .....  .....  .....  .....
.....  .....  .....  .....  .....  .....  .....  .###.  .....  .....  .##..  .....  .....  .....  .....  .....
p      q      r      s      t      u      v      w      x      y      z      {      |      }      ~
.....  .....  .....  .....  .#...  .....  .....  .....  .....  .....  .....  ...##  ..#..  ##...  .....
.....  .....  .....  .....  .#...  .....  .....  .....  .....  .....  .....  ..#..  ..#..  ..#..  .....
####.  .####  #.##.  .####  ####.  #...#  #...#  #...#  #...#  #...#  #####  ..#..  ..#..  ..#..  .#...
#...#  #...#  ##...  #....  .#...  #...#  #...#  #...#  .#.#.  #...#  ...#.  .#...  ..#..  ...#.  #.#.#
#...#  #...#  #....  .###.  .#...  #...#  #...#  #.#.#  ..#..  #...#  ..#..  ..#..  ..#..  ..#..  ...#.
#...#  #...#  #....  ....#  .#...  #..##  .#.#.  #.#.#  .#.#.  #...#  .#...  ..#..  ..#..  ..#..  .....
####.  .####  #....  ####.  ..##.  .##.#  ..#..  .#.#.  #...#  .####  #####  ...##  ..#..  ##...  .....
#....  ....#  .....  .....  .....  .....  .....  .....  .....  ....#  .....  .....  ..#..  .....  .....
#....  ....#  .....  .....  .....  .....  .....  .....  .....  .###.  .....  .....  .....  .....  .....
"##;

/// One glyph: its rows as bit masks (bit 4 is the leftmost column), the first inked column and
/// the number of columns it advances by (without the spacing).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Glyph {
    pub rows: [u8; CELL_H],
    pub first_col: usize,
    pub width: usize,
}

impl Glyph {
    /// Whether column `col` (0 = leftmost of the cell) of row `row` is inked.
    pub fn ink(&self, row: usize, col: usize) -> bool {
        col < CELL_W && self.rows[row] & (1 << (CELL_W - 1 - col)) != 0
    }
}

/// The parsed glyph table, indexed by `code − 32`.
fn table() -> &'static [Glyph; 95] {
    static TABLE: OnceLock<[Glyph; 95]> = OnceLock::new();
    TABLE.get_or_init(parse)
}

fn parse() -> [Glyph; 95] {
    const PER_BAND: usize = 16;
    const STRIDE: usize = CELL_W + 2;
    let lines: Vec<&str> = ART.lines().filter(|l| !l.is_empty()).collect();
    let mut glyphs = [Glyph {
        rows: [0; CELL_H],
        first_col: 0,
        width: SPACE_W,
    }; 95];
    for (index, glyph) in glyphs.iter_mut().enumerate() {
        let code = 32 + index as u8;
        let (band, slot) = (index / PER_BAND, index % PER_BAND);
        let header = lines[band * (CELL_H + 1)];
        let named = header
            .as_bytes()
            .get(slot * STRIDE)
            .copied()
            .unwrap_or(b' ');
        debug_assert_eq!(named, code, "font band {band} is out of order");
        let mut rows = [0u8; CELL_H];
        for (r, row) in rows.iter_mut().enumerate() {
            let line = lines[band * (CELL_H + 1) + 1 + r].as_bytes();
            for c in 0..CELL_W {
                if line.get(slot * STRIDE + c) == Some(&b'#') {
                    *row |= 1 << (CELL_W - 1 - c);
                }
            }
        }
        let used = rows.iter().fold(0u8, |acc, r| acc | r);
        let (first_col, width) = if code.is_ascii_digit() {
            (0, CELL_W)
        } else if used == 0 {
            (0, SPACE_W)
        } else {
            let first = used.leading_zeros() as usize - (8 - CELL_W);
            let last = CELL_W - 1 - used.trailing_zeros() as usize;
            (first, last + 1 - first)
        };
        *glyph = Glyph {
            rows,
            first_col,
            width,
        };
    }
    glyphs
}

/// The glyph of `c`; characters outside printable ASCII are drawn as `?`.
pub(crate) fn glyph(c: char) -> &'static Glyph {
    let code = if (' '..='~').contains(&c) {
        c as usize
    } else {
        '?' as usize
    };
    &table()[code - 32]
}

/// Width and height in font units (scale 1) of `text` on one line: the sum of the glyph widths
/// and the spacing between them, and the full cell height.
pub(crate) fn measure(text: &str) -> (usize, usize) {
    let mut w = 0;
    for (i, c) in text.chars().enumerate() {
        if i > 0 {
            w += SPACING;
        }
        w += glyph(c).width;
    }
    (w, CELL_H)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_band_is_complete_and_in_order() {
        let t = parse();
        assert_eq!(glyph('A').rows, t[('A' as usize) - 32].rows);
        // The art has 6 bands of 10 lines, each row line as long as its glyphs.
        let lines: Vec<&str> = ART.lines().filter(|l| !l.is_empty()).collect();
        assert_eq!(lines.len(), 6 * (CELL_H + 1));
        for (i, line) in lines.iter().enumerate() {
            if i % (CELL_H + 1) != 0 {
                assert_eq!((line.len() + 2) % (CELL_W + 2), 0, "line {i}: {line:?}");
            }
        }
    }

    #[test]
    fn widths_are_proportional_except_digits() {
        assert_eq!(glyph('1').width, CELL_W);
        assert_eq!(glyph('i').width, 3);
        assert_eq!(glyph('.').width, 1);
        assert_eq!(glyph('M').width, 5);
        assert_eq!(glyph(' ').width, SPACE_W);
        assert_eq!(glyph('\u{e9}'), glyph('?'));
        assert_eq!(measure("ab"), (5 + 1 + 5, CELL_H));
    }
}
