// Copyright 2026 The tactfunc Authors.
//
// `tactfunc bench knn`: FLANN kd-forest / k-means at several checks against brute force
// (indexes built with BuildKnnIndex, estimation/knn/knn_index.h): recall@8, median ms per
// query, build time.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <sstream>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/bench/fit_common.h"
#include "apps/command.h"
#include "estimation/functaset/functaset.h"
#include "estimation/knn/knn_index.h"

namespace tactfunc::apps::bench {
namespace {

struct KnnFlags {
  std::string functaset;
  std::string sensor;
  int synthetic = 0;
  int queries = 1000;
  bool json = false;
};

// n x 64 vectors near a 16-dimensional subspace, in 64 clusters (docs/FITTING.md's set).
Functaset::LatentMatrix SyntheticLatents(int n, std::uint64_t seed) {
  const int d = 64, sub = 16, clusters = 64;
  std::mt19937_64 rng(42);  // the subspace and centres are fixed; `seed` draws the points
  std::normal_distribution<float> normal(0.0f, 1.0f);
  Eigen::MatrixXf basis(d, sub), centres(sub, clusters);
  for (int i = 0; i < basis.size(); ++i) basis.data()[i] = normal(rng) / std::sqrt(float(sub));
  for (int i = 0; i < centres.size(); ++i) centres.data()[i] = 2.0f * normal(rng);
  std::mt19937_64 points(seed);
  std::uniform_int_distribution<int> pick(0, clusters - 1);
  Functaset::LatentMatrix out(n, d);
  for (int i = 0; i < n; ++i) {
    Eigen::VectorXf local = centres.col(pick(points));
    for (int k = 0; k < sub; ++k) local[k] += 0.5f * normal(points);
    Eigen::VectorXf v = basis * local;
    for (int k = 0; k < d; ++k) v[k] += 0.02f * normal(points);
    out.row(i) = v.transpose();
  }
  return out;
}

struct KnnRow {
  std::string index;
  int checks = 0;  // 0 = exact
  double build_ms = 0, recall = 1, ms_median = 0, ms_p90 = 0, speedup = 1;
};

void RunKnnBench(const KnnFlags& flags) {
  Functaset::LatentMatrix base, queries;
  std::string source;
  if (flags.synthetic > 0) {
    base = SyntheticLatents(flags.synthetic, 1);
    queries = SyntheticLatents(flags.queries, 2);
    source = "synthetic: " + std::to_string(flags.synthetic) +
             " x 64 vectors near a 16-dim subspace, 64 clusters; " + std::to_string(flags.queries) +
             " held-out queries from the same distribution";
  } else {
    if (flags.functaset.empty()) throw UsageError("give --functaset F or --synthetic N");
    const Functaset functaset = Functaset::Load(flags.functaset);
    SensorKind sensor;
    if (flags.sensor.empty()) {
      if (functaset.sensors().empty()) throw DatasetError(flags.functaset + ": holds no sensor");
      sensor = functaset.sensors()[0];
    } else if (!SensorKindFromString(flags.sensor, &sensor)) {
      throw UsageError("--sensor: expected bubble or gelslim, got '" + flags.sensor + "'");
    }
    if (!functaset.has_sensor(sensor)) {
      throw DatasetError(flags.functaset + ": has no " + std::string(ToString(sensor)) +
                         " latents");
    }
    base = functaset.Latents(sensor, Split::kTrain);
    queries = functaset.Latents(sensor, Split::kTest);
    if (queries.rows() > flags.queries) queries.conservativeResize(flags.queries, Eigen::NoChange);
    if (base.rows() == 0 || queries.rows() == 0) {
      throw DatasetError(flags.functaset +
                         ": needs train latents (the index) and test latents "
                         "(the queries) of " +
                         std::string(ToString(sensor)));
    }
    source = flags.functaset + " " + ToString(sensor) + ": " + std::to_string(base.rows()) + " x " +
             std::to_string(base.cols()) + " train latents, " + std::to_string(queries.rows()) +
             " test latents as queries";
  }
  const int d = static_cast<int>(base.cols()), k = 8;
  const std::int64_t nq = queries.rows();
  std::cout << "bench knn: " << source << ", k = " << k << "\n";

  auto time_queries = [&](const KnnIndex& index, KnnRow* row) {
    std::vector<float> distances(k);
    std::vector<std::int64_t> labels(k);
    std::vector<double> ms(nq);
    for (std::int64_t q = 0; q < nq; ++q) {
      const Clock::time_point start = Clock::now();
      index.Search(queries.row(q).data(), 1, k, distances.data(), labels.data());
      ms[q] = MsSince(start);
    }
    row->ms_median = Median(ms);
    row->ms_p90 = Quantile(ms, 0.9);
  };

  std::vector<KnnRow> rows;
  std::unique_ptr<KnnIndex> exact;
  {
    KnnRow row{"brute_force", 0};
    const Clock::time_point start = Clock::now();
    exact = BuildKnnIndex(base, KnnIndexOptions());
    row.build_ms = MsSince(start);
    time_queries(*exact, &row);
    rows.push_back(row);
  }
  const double brute_ms = rows[0].ms_median;
  struct Config {
    std::string name;
    KnnIndexOptions options;
  };
  std::vector<Config> configs;
  for (int trees : {4, 8}) {
    KnnIndexOptions o;
    o.type = "kd_forest";
    o.flann.trees = trees;
    configs.push_back({"kd_forest trees=" + std::to_string(trees), o});
  }
  {
    KnnIndexOptions o;
    o.type = "kmeans";
    configs.push_back({"kmeans branching=32", o});
  }
  for (const Config& c : configs) {
    const Clock::time_point start = Clock::now();
    const std::unique_ptr<KnnIndex> built = BuildKnnIndex(base, c.options);
    const double build_ms = MsSince(start);
    auto& index = dynamic_cast<FlannKnnIndex&>(*built);
    for (int checks : {16, 32, 64, 128, 256, 512}) {
      FlannKnnIndex::SearchParams params;
      params.checks = checks;
      index.set_search_params(params);
      KnnRow row{c.name, checks};
      row.build_ms = build_ms;
      row.recall = Recall(index, *exact, queries.data(), nq, k);
      time_queries(index, &row);
      row.speedup = brute_ms / row.ms_median;
      rows.push_back(row);
    }
  }
  const KnnRow* best = nullptr;
  for (const KnnRow& r : rows) {
    if (r.checks > 0 && r.recall >= 0.95 && r.speedup >= 10 &&
        (best == nullptr || r.speedup > best->speedup)) {
      best = &r;
    }
  }
  std::ostringstream md;
  md << "| index | build ms | checks | recall@8 | ms/query median | ms/query p90 | speed-up vs "
        "brute force |\n";
  md << "|---|---|---|---|---|---|---|\n";
  for (const KnnRow& r : rows) {
    md << "| " << r.index << " | " << Ms(r.build_ms) << " | "
       << (r.checks ? std::to_string(r.checks) : "exact") << " | " << FormatFixed(r.recall, 3)
       << " | " << Ms(r.ms_median) << " | " << Ms(r.ms_p90) << " | " << FormatFixed(r.speedup, 1)
       << "x |\n";
  }
  std::cout << md.str();
  const std::string verdict =
      best != nullptr
          ? "met: " + best->index + " at " + std::to_string(best->checks) + " checks, recall@8 " +
                FormatFixed(best->recall, 3) + ", " + FormatFixed(best->speedup, 1) +
                "x faster than brute force"
          : "NOT met: no FLANN setting reaches recall@8 >= 0.95 at >= 10x the brute-force speed on "
            "this set";
  std::cout << "target recall@8 >= 0.95 at >= 10x faster than brute force: " << verdict << "\n";
  std::cout << "(one query at a time, std::chrono per query, median over the queries)\n";
  if (flags.json) {
    nlohmann::json list = nlohmann::json::array();
    for (const KnnRow& r : rows) {
      list.push_back({{"index", r.index},
                      {"checks", r.checks},
                      {"build_ms", r.build_ms},
                      {"recall_at_8", r.recall},
                      {"ms_median", r.ms_median},
                      {"ms_p90", r.ms_p90},
                      {"speedup", r.speedup}});
    }
    EmitJson({{"bench", "knn"},
              {"source", source},
              {"size", base.rows()},
              {"dim", d},
              {"queries", nq},
              {"rows", list},
              {"target_met", best != nullptr},
              {"target", verdict},
              {"machine", MachineDescription()}});
  }
}

}  // namespace

void RegisterKnnSuite(CLI::App* bench, CommandBody* selected) {
  {
    auto flags = std::make_shared<KnnFlags>();
    CLI::App* sub = bench->add_subcommand(
        "knn",
        "FLANN kd-forest and k-means at several checks vs brute force: recall@8, median ms per "
        "query, build time, and whether recall@8 >= 0.95 at >= 10x brute-force speed is met.");
    sub->add_option("--functaset", flags->functaset,
                    "Functaset: its train latents are the index, its test latents the queries");
    sub->add_option("--sensor", flags->sensor, "bubble or gelslim (default: the first it holds)");
    sub->add_option("--synthetic", flags->synthetic,
                    "Instead: N synthetic 64-d vectors (clusters near a 16-d subspace)")
        ->check(CLI::Range(1, 10000000));
    sub->add_option("--queries", flags->queries, "At most this many queries (default 1000)")
        ->check(CLI::Range(1, 1000000));
    sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
    sub->callback([flags, selected]() { *selected = [flags]() { RunKnnBench(*flags); }; });
  }
}

}  // namespace tactfunc::apps::bench
