//! Simulations of reflectors at continuous depths, or put on the grid by a response other than
//! delta: the scene is rendered from [`Returns`], whose depths `range.npy` holds.

use super::simulation::SimulationRequest;
use super::*;
use crate::lidar::{
    paper_returns, paper_scene, random_opaque_scene, random_returns, semi_transparent_scene,
    transparent_returns, Response, Returns, Simulation, SimulationSpec,
};

impl SimulationRequest {
    /// The response the scene is rendered with: `kernel`, or by default the triangle at
    /// continuous depths and delta on the grid.
    pub fn response(&self) -> Response {
        self.kernel.clone().unwrap_or(if self.continuous {
            Response::Triangle
        } else {
            Response::Delta
        })
    }

    /// Whether the scene is rendered from returns: at continuous depths, or with a response
    /// other than delta.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`depth`) for continuous depths with the delta response,
    /// which holds depths on the grid only.
    pub fn renders_returns(&self) -> Result<bool> {
        let response = self.response();
        if self.continuous && response.is_delta() {
            return Err(Error::param(
                "depth",
                "continuous depths need a response other than `kernel=delta`, which holds \
                 depths on the grid only: triangle or gaussian:S",
            ));
        }
        Ok(self.continuous || !response.is_delta())
    }

    /// Records in `sim` what the request supplied: where its scene came from and, for a scene
    /// rendered from returns, the returns (whose depths [`write_simulation`] writes to
    /// `range.npy`) and the response.
    ///
    /// # Errors
    /// As [`returns`](Self::returns).
    pub fn describe<T: Real>(&self, sim: &mut Simulation<T>) -> Result<()> {
        sim.scene_source = self.scene_source();
        sim.returns = self.returns()?;
        sim.response = sim.returns.as_ref().map(|_| self.response());
        Ok(())
    }

    /// The returns the scene is rendered from (`None` when it is not): the scene's reflectors
    /// at continuous depths (the paper's, random, semi-transparent, or the png maps' depths
    /// unrounded), or on the grid.
    ///
    /// # Errors
    /// As [`spec`](Self::spec) and [`supplied_scene`](Self::supplied_scene).
    pub fn returns(&self) -> Result<Option<Returns>> {
        if !self.renders_returns()? {
            return Ok(None);
        }
        let g = self.geometry;
        let seed = SimulationSpec::new(g, self.pulse_len, self.seed)
            .seeds()
            .scene();
        let lit = self.lit_fraction.unwrap_or(0.5);
        let grid = !self.continuous;
        let returns = match self.scene.as_str() {
            "paper" if grid => Returns::of_scene(&paper_scene::<f64>(g)?),
            "paper" => paper_returns(g)?,
            "random" if grid => Returns::of_scene(&random_opaque_scene::<f64>(g, lit, seed)?),
            "random" => random_returns(g, lit, seed)?,
            "transparent" if grid => {
                Returns::of_scene(&semi_transparent_scene::<f64>(g, 1..=3.min(g.ks), seed)?)
            }
            "transparent" => transparent_returns(g, seed)?,
            _ => {
                #[cfg(feature = "images")]
                let read = self.read_pngs(std::mem::size_of::<f64>(), |depth, refl, ks| {
                    crate::io::returns_from_pngs(depth, refl, ks)
                })?;
                // Without the feature, read_pngs refuses a png scene before reading.
                #[cfg(not(feature = "images"))]
                let read: Option<Returns> = self.read_pngs(8, |_, _, _| {
                    Err(Error::param(
                        "depth_png",
                        "PNG depth maps need the `images` feature",
                    ))
                })?;
                match read {
                    Some(r) if grid => Returns::new(r.depth.mapv(f64::round), r.amplitude)?,
                    Some(r) => r,
                    None => {
                        return Err(Error::param(
                            "scene",
                            format!("{} has no returns", self.scene),
                        ))
                    }
                }
            }
        };
        Ok(Some(returns))
    }
}
