// Copyright 2026 The tactfunc Authors.
//
// tactfunc show: a contact sheet of a dataset -- per contact and sensor the raw frame,
// the reference and the difference, with the tool's pose drawn as an arrow.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <set>

#include <opencv2/imgproc.hpp>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/output_paths.h"
#include "apps/pictures.h"
#include "estimation/data/dataset.h"
#include "estimation/data/preprocess.h"

namespace tactfunc::apps {
namespace {

struct ShowFlags {
  std::string dir;
  DatasetFlags data;
  std::string out;
  int contacts = 8;
  std::string ids;
  int tile_height = 180;
  bool json = false;
};

// Up to n frame ids, one per tool first (in dataset order), then evenly spread.
std::vector<std::string> PickIds(const Dataset& dataset, int n) {
  std::vector<std::string> ids;
  std::set<std::string> seen_ids, seen_tools;
  for (const FrameRecord& record : dataset.frames()) {
    if (static_cast<int>(ids.size()) >= n) break;
    const std::string tool = record.label ? record.label->tool : "";
    if (seen_ids.count(record.id) || (!tool.empty() && seen_tools.count(tool))) continue;
    seen_ids.insert(record.id);
    if (!tool.empty()) seen_tools.insert(tool);
    ids.push_back(record.id);
  }
  std::vector<std::string> all;
  for (const FrameRecord& record : dataset.frames()) {
    if (all.empty() || all.back() != record.id) all.push_back(record.id);
  }
  for (std::size_t i = 0; static_cast<int>(ids.size()) < n && i < all.size(); ++i) {
    const std::string& id = all[(i * 7919) % all.size()];
    if (seen_ids.insert(id).second) ids.push_back(id);
  }
  return ids;
}

double DifferenceScale(const SensorInfo& info) {
  if (info.normalization_scale > 0) return info.normalization_scale;
  return info.kind == SensorKind::kSoftBubble ? 0.01 : 0.5;
}

void RunShow(const ShowFlags& flags) {
  const std::vector<NamedPath> outputs = {{"--out", flags.out}};
  RefuseOutputsThatAreInputs(outputs, DatasetPathInputs("DIR", flags.dir, flags.data));
  const Dataset dataset = OpenDataset(flags.dir, flags.data);
  RefuseOutputsThatAreInputs(outputs, DatasetFileInputs("DIR", dataset));
  std::vector<std::string> ids =
      flags.ids.empty() ? PickIds(dataset, flags.contacts) : SplitList(flags.ids);
  if (ids.empty()) throw UsageError(flags.dir + ": the dataset has no frames to show");
  std::map<std::pair<std::string, SensorKind>, std::size_t> index;
  for (std::size_t i = 0; i < dataset.frames().size(); ++i) {
    index[{dataset.frames()[i].id, dataset.frames()[i].sensor}] = i;
  }
  const std::vector<SensorKind> sensors = dataset.sensors();
  const int h = flags.tile_height;
  const cv::Scalar kArrow(255, 0, 255);

  std::vector<std::vector<cv::Mat>> grid;
  // Header: column titles.
  {
    std::vector<cv::Mat> header;
    header.push_back(cv::Mat(28, 150, CV_8UC3, kBackground));
    for (SensorKind sensor : sensors) {
      const SensorInfo& info = dataset.sensor_info(sensor);
      const int w = static_cast<int>(std::lround(info.cols * double(h) / info.rows));
      for (const char* title : {"raw", "reference", "difference"}) {
        cv::Mat cell(28, w, CV_8UC3, kBackground);
        PutLabel(cell, std::string(ToString(sensor)) + " " + title, {6, 19}, 0.5);
        header.push_back(cell);
      }
    }
    grid.push_back(header);
  }
  int shown = 0;
  for (const std::string& id : ids) {
    std::vector<cv::Mat> row;
    cv::Mat caption(h, 150, CV_8UC3, kBackground);
    PutLabel(caption, "frame " + id, {6, 22}, 0.5);
    bool any = false;
    for (SensorKind sensor : sensors) {
      const SensorInfo& info = dataset.sensor_info(sensor);
      const auto it = index.find({id, sensor});
      const int w = static_cast<int>(std::lround(info.cols * double(h) / info.rows));
      if (it == index.end()) {
        for (int k = 0; k < 3; ++k) row.push_back(cv::Mat(h, w, CV_8UC3, cv::Scalar(20, 20, 20)));
        continue;
      }
      any = true;
      const FrameRecord& record = dataset.frames()[it->second];
      const Image frame = dataset.LoadFrame(it->second);
      const Image& reference = dataset.FrameReference(it->second);
      cv::Mat tiles[3] = {FitHeight(RawTile(frame, sensor, reference), h),
                          FitHeight(RawTile(reference, sensor, reference), h),
                          FitHeight(DifferenceTile(Difference(frame, reference, sensor),
                                                   DifferenceScale(info)),
                                    h)};
      if (record.label) {
        const PoseLabel& label = *record.label;
        const SE2d& pose = label.sensor_T_object;
        for (cv::Mat& tile : tiles) {
          DrawPoseArrow(tile, info.rows, info.cols, info.pixel_pitch_m, pose.x(), pose.y(),
                        pose.yaw(), kArrow);
        }
        char text[96];
        std::snprintf(text, sizeof(text), "%s d=%.1fmm", ToString(sensor),
                      label.depth_m * 1e3);
        PutLabel(caption, text, {6, sensor == SensorKind::kSoftBubble ? 104 : 122}, 0.42);
        if (sensor == sensors.front()) {
          PutLabel(caption, label.tool, {6, 44}, 0.5, cv::Scalar(255, 0, 255));
          std::snprintf(text, sizeof(text), "x=%.1f y=%.1f mm", pose.x() * 1e3,
                        pose.y() * 1e3);
          PutLabel(caption, text, {6, 64}, 0.42);
          std::snprintf(text, sizeof(text), "yaw=%.0f deg", pose.yaw() * kDeg);
          PutLabel(caption, text, {6, 82}, 0.42);
        }
      }
      for (cv::Mat& tile : tiles) row.push_back(tile);
    }
    if (!any) throw UsageError(flags.dir + ": no frame with id '" + id + "'");
    row.insert(row.begin(), caption);
    grid.push_back(row);
    ++shown;
  }
  const cv::Mat sheet = TileGrid(grid);
  WritePicture(flags.out, sheet);
  std::cout << "show: wrote a " << sheet.cols << "x" << sheet.rows << " contact sheet of "
            << shown << " contacts to " << flags.out << "\n";
  if (flags.json) {
    EmitJson({{"out", flags.out}, {"contacts", shown}, {"width", sheet.cols},
              {"height", sheet.rows}});
  }
}

}  // namespace

void RegisterShow(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<ShowFlags>();
  CLI::App* sub = app.add_subcommand(
      "show",
      "Write a contact sheet (raw, reference, difference, pose arrow) of a dataset as PNG.");
  sub->add_option("dir", flags->dir, "Dataset folder")->required();
  sub->add_option("--out", flags->out, "Output PNG")->required();
  sub->add_option("--contacts", flags->contacts,
                  "How many contacts (rows) to show; one per tool first")
      ->check(CLI::Range(1, 200));
  AddDatasetFlags(sub, &flags->data);
  sub->add_option("--ids", flags->ids, "Comma-separated frame ids to show instead");
  sub->add_option("--tile-height", flags->tile_height, "Tile height in pixels")
      ->check(CLI::Range(40, 1000));
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunShow(*flags); }; });
}

}  // namespace tactfunc::apps
