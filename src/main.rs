//! The `rdlidar` command line.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use rdlidar::operator::{
    BoxedOperator, ConvMethod, ConvMode, Convolve1D, DenseMatrix, Diagonal, DotTest, Gradient2D,
    HStack, Identity, NalgebraMatrix, OperatorExt, Restriction, SparseMatrix, VStack, Zero,
};
use rdlidar::Real;

/// Compressive time-of-flight lidar by random demodulation.
#[derive(Parser, Debug)]
#[command(name = "rdlidar", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the dot test on every operator and combinator, in f32 and f64, and print the gaps.
    ///
    /// Example: `rdlidar selfcheck --seed 3`
    Selfcheck {
        /// Seed of the random operators and test vectors.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
}

/// Deterministic values in [−1, 1) (a small LCG; the operators only need to be generic).
fn values(len: usize, seed: u64) -> Vec<f64> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..len)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        })
        .collect()
}

/// One instance of every operator and combinator, named.
fn catalogue<T: Real>(seed: u64) -> rdlidar::Result<Vec<(&'static str, BoxedOperator<T>)>> {
    let c = |v: Vec<f64>| v.into_iter().map(T::of_f64).collect::<Vec<T>>();
    let (m, n) = (23, 17);
    let dense = || -> rdlidar::Result<DenseMatrix<T>> {
        DenseMatrix::new(ndarray::Array2::from_shape_vec((m, n), c(values(m * n, seed))).unwrap())
    };
    let mut sp = sprs::TriMat::new((m, n));
    for (k, v) in values(m * n, seed + 1)
        .into_iter()
        .enumerate()
        .filter(|(k, _)| k % 4 == 0)
    {
        sp.add_triplet(k / n, k % n, T::of_f64(v));
    }
    let pulse: Vec<T> = c(values(300, seed + 2)
        .into_iter()
        .map(|v| if v > 0.0 { 1.0 } else { 0.0 })
        .collect());
    Ok(vec![
        ("Identity", Identity::<T>::new(n).boxed()),
        ("Zero", Zero::<T>::new(m, n).boxed()),
        ("Diagonal", Diagonal::new(c(values(n, seed + 3)))?.boxed()),
        (
            "Restriction (repeated indices)",
            Restriction::<T>::new(n, vec![3, 1, 3, 16, 0, 3])?.boxed(),
        ),
        ("Gradient2D 12x9", Gradient2D::<T>::new(12, 9)?.boxed()),
        (
            "Convolve1D direct, full",
            Convolve1D::new(
                7,
                40,
                c(values(9, seed + 4)),
                ConvMode::Full,
                ConvMethod::Direct,
            )?
            .boxed(),
        ),
        (
            "Convolve1D direct, same",
            Convolve1D::new(
                7,
                40,
                c(values(9, seed + 4)),
                ConvMode::Same,
                ConvMethod::Direct,
            )?
            .boxed(),
        ),
        (
            "Convolve1D direct, valid",
            Convolve1D::new(
                7,
                40,
                c(values(9, seed + 4)),
                ConvMode::Valid,
                ConvMethod::Direct,
            )?
            .boxed(),
        ),
        (
            "Convolve1D FFT, full (0/1 pulse 300)",
            Convolve1D::new(7, 40, pulse.clone(), ConvMode::Full, ConvMethod::Fft)?.boxed(),
        ),
        (
            "Convolve1D FFT, same",
            Convolve1D::new(7, 400, pulse.clone(), ConvMode::Same, ConvMethod::Fft)?.boxed(),
        ),
        (
            "Convolve1D FFT, valid",
            Convolve1D::new(7, 400, pulse, ConvMode::Valid, ConvMethod::Fft)?.boxed(),
        ),
        ("DenseMatrix", dense()?.boxed()),
        (
            "NalgebraMatrix",
            NalgebraMatrix::new(nalgebra::DMatrix::from_vec(
                m,
                n,
                c(values(m * n, seed + 5)),
            ))?
            .boxed(),
        ),
        ("SparseMatrix", SparseMatrix::new(sp.to_csr())?.boxed()),
        (
            "Compose",
            dense()?
                .compose(Diagonal::new(c(values(n, seed + 6)))?)?
                .boxed(),
        ),
        ("Adjoint", dense()?.adjoint().boxed()),
        ("Scaled", dense()?.scaled(T::of_f64(-2.5))?.boxed()),
        ("Sum", dense()?.plus(Zero::new(m, n))?.boxed()),
        ("Difference", dense()?.minus(dense()?)?.boxed()),
        ("Normal", dense()?.normal().boxed()),
        (
            "VStack",
            VStack::new(vec![dense()?.boxed(), Identity::new(n).boxed()])?.boxed(),
        ),
        (
            "HStack",
            HStack::new(vec![dense()?.boxed(), Identity::new(m).boxed()])?.boxed(),
        ),
        (
            "BlockDiag",
            rdlidar::operator::BlockDiag::new(vec![
                dense()?.boxed(),
                Gradient2D::new(3, 4)?.boxed(),
            ])?
            .boxed(),
        ),
        ("Counted", dense()?.counted().boxed()),
    ])
}

fn selfcheck(seed: u64) -> rdlidar::Result<bool> {
    let ops32 = catalogue::<f32>(seed)?;
    let ops64 = catalogue::<f64>(seed)?;
    println!("dot test |<Ax,y> - <x,A*y>| / max(|Ax||y|, |x||A*y|), seed {seed}");
    println!("{:<38} {:>12} {:>12}", "operator", "gap f32", "gap f64");
    let mut ok = true;
    for ((name, a32), (_, a64)) in ops32.iter().zip(&ops64) {
        let r32 = DotTest::new().seed(seed).measure(a32);
        let r64 = DotTest::new().seed(seed).measure(a64);
        let flag = if r32.passed() && r64.passed() {
            ""
        } else {
            "  FAILED"
        };
        ok &= flag.is_empty();
        println!("{name:<38} {:>12.2e} {:>12.2e}{flag}", r32.gap, r64.gap);
    }
    println!(
        "tolerances: f32 {:.0e}, f64 {:.0e}",
        f32::DOT_TEST_TOL,
        f64::DOT_TEST_TOL
    );
    Ok(ok)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        None => {
            println!("rdlidar {}", env!("CARGO_PKG_VERSION"));
            println!("subcommands: selfcheck (run `rdlidar --help`)");
            ExitCode::SUCCESS
        }
        Some(Command::Selfcheck { seed }) => match selfcheck(seed) {
            Ok(true) => ExitCode::SUCCESS,
            Ok(false) => {
                eprintln!("error: some operators failed the dot test");
                ExitCode::FAILURE
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        },
    }
}
