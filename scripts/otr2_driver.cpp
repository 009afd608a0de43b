// Runs CGAL's Optimal_transportation_reconstruction_2 on a weighted point file,
// for scripts/compare_reference.py.
//
//   otr2_driver INPUT OUTPUT N_VERTICES [SAMPLE_SIZE [RELOCATION]]
//
// INPUT: one point per line, "x y" or "x y mass". SAMPLE_SIZE 0 (the
// default) is CGAL's exhaustive queue, RELOCATION its relocation steps
// between two collapses (default 2): CGAL's own defaults unless given.
// OUTPUT: "seconds S", then "vertices V" and V lines "x y", "edges E" and
// E lines "i j", "isolated I" and I lines "i", all indices into the
// vertices. S is the time of construction, simplification and output.

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Optimal_transportation_reconstruction_2.h>
#include <CGAL/property_map.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <iterator>
#include <sstream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

typedef CGAL::Exact_predicates_inexact_constructions_kernel K;
typedef K::FT FT;
typedef K::Point_2 Point;
typedef std::pair<Point, FT> WeightedPoint;
typedef CGAL::First_of_pair_property_map<WeightedPoint> PointMap;
typedef CGAL::Second_of_pair_property_map<WeightedPoint> MassMap;
typedef CGAL::Optimal_transportation_reconstruction_2<K, PointMap, MassMap> Otr2;

static bool read_points(const char* path, std::vector<WeightedPoint>& out) {
  std::ifstream in(path);
  if (!in) return false;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    double x, y, m = 1.0;
    if (!(fields >> x >> y)) continue;
    if (!(fields >> m)) m = 1.0;
    out.emplace_back(Point(x, y), FT(m));
  }
  return !out.empty();
}

int main(int argc, char** argv) {
  if (argc < 4) {
    std::cerr << "usage: otr2_driver INPUT OUTPUT N_VERTICES [SAMPLE_SIZE [RELOCATION]]\n";
    return 2;
  }
  std::vector<WeightedPoint> points;
  if (!read_points(argv[1], points)) {
    std::cerr << "otr2_driver: cannot read points from " << argv[1] << "\n";
    return 1;
  }
  const std::size_t n_vertices = std::strtoul(argv[3], nullptr, 10);
  const std::size_t sample_size = argc > 4 ? std::strtoul(argv[4], nullptr, 10) : 0;
  const unsigned int relocation = argc > 5 ? std::strtoul(argv[5], nullptr, 10) : 2;

  const auto start = std::chrono::steady_clock::now();
  Otr2 otr2(points, PointMap(), MassMap(), sample_size, true, relocation);
  otr2.run_until(n_vertices);
  std::vector<Point> vertices;
  std::vector<std::size_t> isolated;
  std::vector<std::pair<std::size_t, std::size_t> > edges;
  otr2.indexed_output(std::back_inserter(vertices), std::back_inserter(isolated), std::back_inserter(edges));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  std::ofstream out(argv[2]);
  out.precision(17);
  out << "seconds " << seconds << "\n";
  out << "vertices " << vertices.size() << "\n";
  for (const Point& p : vertices) out << p.x() << " " << p.y() << "\n";
  out << "edges " << edges.size() << "\n";
  for (const auto& e : edges) out << e.first << " " << e.second << "\n";
  out << "isolated " << isolated.size() << "\n";
  for (std::size_t i : isolated) out << i << "\n";
  return out ? 0 : 1;
}
