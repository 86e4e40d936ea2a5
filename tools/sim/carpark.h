// A generated outdoor site: a car park of about 200 m x 200 m (asphalt with painted bays, lane
// dashes and arrows, kerbed islands with lamp posts and trees, parked cars, building facades to the
// north, a sky), deterministic from a seed, with the paths driven and walked through it, and the
// time-of-day lighting (daylight scale, street lamps). World frame: x east, y north, z up, metres,
// origin at the site centre. See docs/sim-scene.md, "Car park site".
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tools/sim/scene.h"

namespace evloc::sim {

// What the car park generator builds.
struct CarParkOptions {
  // Seed of the layout (parked cars, colours, jitter, buildings).
  uint64_t seed = 1;
  // Number of modules (a row of bays, a driving lane, a row of bays, an island) from south to
  // north; each is 20 m deep.
  int modules = 8;
  // Number of bays per row along x (2.5 m each).
  int bays_per_row = 64;
  // Probability that a bay holds a parked car, in [0, 1].
  double occupancy = 0.55;
  // Side of the square asphalt tiles the ground is split into, metres (bounds the renderer's
  // texture indices and the map sampling per surface).
  double ground_tile_m = 20;
  // Marks on the asphalt per square metre: stains, oil spots and small repairs (discs and
  // rectangles of 0.05-0.5 m, a little darker or lighter than the asphalt), the fine texture of
  // real asphalt that structure from motion matches on. 0 (the default) leaves the ground as it
  // has always been rendered; any value leaves the rest of the layout unchanged (the marks draw
  // from a random sequence of their own).
  double ground_marks_per_m2 = 0;

  // Throws InvalidArgumentError for fewer than 1 module or 4 bays, occupancy outside [0, 1], a
  // non-positive tile size, or a negative or non-finite mark density (or above 20 per m^2).
  void Check() const;
};

// The site and its paths.
struct CarPark {
  // The scene (lit by day: daylight 1, sky 0.8, street lamps in `lamps` but not in
  // scene.point_lights; see ApplyTimeOfDay).
  Scene scene;
  // The street lamps (night intensity).
  std::vector<PointLight> lamps;
  // Centre line y of each driving lane, south to north, metres.
  std::vector<double> lane_y;
  // West and east ends of the bays along x, metres.
  double bays_min_x = 0, bays_max_x = 0;
  // The vehicle route (2D, sampled every 0.1 m): east along lane 0, a half circle at the east
  // end into lane 1, west along it, and so on through every lane (a serpentine).
  std::vector<Eigen::Vector2d> drive_route;
  // A pedestrian's path: along the southern edge of lane 0 eastwards, keeping 1 m from the bays.
  std::vector<Eigen::Vector2d> walk_route;
  // The survey walking loops: one closed loop per lane (east along its south edge, back west along
  // its north edge), concatenated.
  std::vector<Eigen::Vector2d> survey_walk_route;
};

// Generates the car park. Deterministic for a seed. Throws InvalidArgumentError when the options
// fail Check().
CarPark MakeCarPark(const CarParkOptions& options = {});

// The `--time-of-day` settings.
enum class TimeOfDay { kDay, kDusk, kNight };

// "day", "dusk" or "night".
std::string TimeOfDayName(TimeOfDay time);
// Parses a time-of-day name; throws InvalidArgumentError naming the valid values otherwise.
TimeOfDay ParseTimeOfDay(const std::string& name);

// Sets the scene's daylight, sky and point lights for a time of day (the sky renders as
// sky * daylight): day = daylight 1, sky 0.8, lamps off; dusk = daylight 0.15, sky 0.8, lamps on;
// night = daylight 0.01, sky 0.2, lamps on. `lamps` are the lamps (street lights).
void ApplyTimeOfDay(TimeOfDay time, const std::vector<PointLight>& lamps, Scene* scene);

// A 2D polyline resampled every `spacing` metres along its length (the last point kept).
std::vector<Eigen::Vector2d> ResamplePolyline(const std::vector<Eigen::Vector2d>& points,
                                              double spacing);

}  // namespace evloc::sim
