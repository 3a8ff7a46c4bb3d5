//! `FullyConnected::accumulate` against wide sums on random shapes, at every row-kernel level this
//! CPU runs: on aarch64 NEON with `SDOT` (if the CPU has it), NEON without, portable; on x86-64
//! AVX-512 VNNI and AVX-VNNI (if present), AVX2, portable. int8 inputs with int32 accumulators (every column remainder, rows
//! not multiples of four, -128/127 extremes, sums that wrap) and int16 inputs with int64
//! accumulators (widths across the 512-column chunks, -32768/32767 extremes).
//!
//! A plain program (`harness = false`): libtest runs each test on a thread, and threads hang
//! under the qemu-aarch64 7.2 that `scripts/aarch64.sh --test` runs this with.
use frmd_core::kernels::{FullyConnected, LayerInput};
use frmd_core::rng::SplitMix64;

/// One random layer: `rows x columns` weights, bias, input.
struct Case<X, A> {
    rows: usize,
    columns: usize,
    weights: Vec<i8>,
    bias: Vec<A>,
    input: Vec<X>,
}

fn draw(rng: &mut SplitMix64, below: usize) -> usize {
    (rng.next_u64() % below as u64) as usize
}

fn int8_case(rng: &mut SplitMix64, case: usize) -> Case<i8, i32> {
    let columns = 1 + draw(rng, 300);
    let rows = 1 + draw(rng, 11);
    let extreme = case.is_multiple_of(5);
    let byte = |rng: &mut SplitMix64| match (extreme, rng.next_u64() % 2) {
        (true, 0) => -128,
        (true, _) => 127,
        (false, _) => (rng.next_u64() >> 8) as i8,
    };
    Case {
        rows,
        columns,
        weights: (0..rows * columns).map(|_| byte(rng)).collect(),
        bias: (0..rows).map(|_| rng.next_u64() as i32).collect(),
        input: (0..columns).map(|_| byte(rng)).collect(),
    }
}

fn int16_case(rng: &mut SplitMix64, case: usize) -> Case<i16, i64> {
    let columns = 1 + draw(rng, 1100);
    let rows = 1 + draw(rng, 11);
    let extreme = case.is_multiple_of(5);
    let weights = (0..rows * columns)
        .map(|_| match (extreme, rng.next_u64() % 2) {
            (true, 0) => -127,
            (true, _) => 127,
            (false, _) => ((rng.next_u64() >> 8) as i8).max(-127),
        })
        .collect();
    let input = (0..columns)
        .map(|_| match (extreme, rng.next_u64() % 2) {
            (true, 0) => i16::MIN,
            (true, _) => i16::MAX,
            (false, _) => (rng.next_u64() >> 8) as i16,
        })
        .collect();
    Case {
        rows,
        columns,
        weights,
        bias: (0..rows).map(|_| (rng.next_u64() as i64) >> 20).collect(),
        input,
    }
}

/// `bias[o] + sum w[o][i] * x[i]` in i128.
fn wide<X: Copy + Into<i64>, A: Copy + Into<i64>>(case: &Case<X, A>) -> Vec<i128> {
    case.weights
        .chunks_exact(case.columns)
        .zip(&case.bias)
        .map(|(row, bias)| {
            let dot: i128 = row
                .iter()
                .zip(&case.input)
                .map(|(w, x)| i128::from(*w) * i128::from((*x).into()))
                .sum();
            i128::from((*bias).into()) + dot
        })
        .collect()
}

/// The levels to run: name and a switch that selects it.
#[cfg(target_arch = "aarch64")]
fn levels() -> Vec<(&'static str, fn())> {
    use frmd_core::kernels::aarch64;
    let mut levels: Vec<(&'static str, fn())> = Vec::new();
    if aarch64::dotprod_supported() {
        levels.push(("neon+sdot", || {
            aarch64::set_neon_enabled(true);
            aarch64::set_dotprod_enabled(true);
        }));
    } else {
        eprintln!("no FEAT_DotProd on this CPU: the SDOT path is not exercised");
    }
    levels.push(("neon", || {
        aarch64::set_neon_enabled(true);
        aarch64::set_dotprod_enabled(false);
    }));
    levels.push(("portable", || {
        aarch64::set_neon_enabled(false);
    }));
    levels
}

#[cfg(target_arch = "x86_64")]
fn levels() -> Vec<(&'static str, fn())> {
    use frmd_core::kernels::x86;
    let mut levels: Vec<(&'static str, fn())> = Vec::new();
    if x86::avx512_supported() {
        levels.push(("avx512-vnni", || {
            x86::set_avx2_enabled(true);
            x86::set_avx512_enabled(true);
        }));
    }
    if x86::avx_vnni_supported() {
        levels.push(("avx-vnni", || {
            x86::set_avx2_enabled(true);
            x86::set_avx512_enabled(false);
            x86::set_avx_vnni_enabled(true);
        }));
    }
    levels.push(("avx2", || {
        x86::set_avx2_enabled(true);
        x86::set_avx512_enabled(false);
        x86::set_avx_vnni_enabled(false);
    }));
    levels.push(("portable", || {
        x86::set_avx2_enabled(false);
    }));
    levels
}

#[cfg(not(any(target_arch = "aarch64", target_arch = "x86_64")))]
fn levels() -> Vec<(&'static str, fn())> {
    vec![("default", || {})]
}

fn main() {
    let mut rng = SplitMix64::new(0x524F_5753);
    let int8: Vec<_> = (0..300).map(|case| int8_case(&mut rng, case)).collect();
    let int16: Vec<_> = (0..120).map(|case| int16_case(&mut rng, case)).collect();
    // Four rows whose int32 sums exceed i32::MAX and wrap.
    let wrap_columns = 131_088;
    let wrapping = Case {
        rows: 4,
        columns: wrap_columns,
        weights: vec![-128; 4 * wrap_columns],
        bias: vec![0; 4],
        input: vec![-128; wrap_columns],
    };
    let mut checked = 0;
    for (level, select) in levels() {
        select();
        let int8_cases = int8.iter().chain([&wrapping]);
        let layers = check(level, int8_cases, LayerInput::Int8, |sum| sum as i32)
            + check(level, &int16, LayerInput::Int16, |sum| sum as i64);
        println!("row kernels, {level}: {layers} layers equal the wide sums");
        checked += layers;
    }
    assert!(checked > 0);
}

/// `FullyConnected::accumulate` of every case against its wide sums (narrowed by `narrow`: int32
/// accumulators wrap); returns the number of layers checked.
fn check<'a, X, A>(
    level: &str,
    cases: impl IntoIterator<Item = &'a Case<X, A>>,
    input: fn(&'a [X]) -> LayerInput<'a>,
    narrow: fn(i128) -> A,
) -> usize
where
    X: Copy + Into<i64> + 'a,
    A: frmd_core::kernels::Accumulator + Into<i64> + 'a,
{
    let mut checked = 0;
    for case in cases {
        let layer = FullyConnected::new(case.columns, case.rows, &case.weights, &case.bias);
        let mut acc = vec![A::ZERO; case.rows];
        layer
            .accumulate(input(&case.input), &mut acc)
            .expect("valid layer");
        let expected: Vec<A> = wide(case).into_iter().map(narrow).collect();
        assert_eq!(acc, expected, "{level}: {}x{}", case.rows, case.columns);
        checked += 1;
    }
    checked
}
