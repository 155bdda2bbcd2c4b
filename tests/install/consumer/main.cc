// Uses one public type from each installed module, and hands Eigen heap objects across
// the library boundary both ways: a consumer compiled without tactfunc's -march=native
// frees buffers the library allocated, and the library resizes buffers the consumer
// allocated (docs/BUILD.md, "Eigen's allocator").
#include <cmath>
#include <cstdio>

#include "estimation/data/preprocess.h"
#include "estimation/data/trunk_targets.h"
#include "models/trunk/latent_modulated_siren.h"
#include "models/simulator/contact_simulator.h"
#include "samplers/step_size_schedule.h"

int main() {
  using namespace tactfunc;
  const ContactSimulator simulator;
  Contact contact;
  contact.tool = "rod";
  contact.depth_m = 0.004;
  const auto rendering = simulator.Render(SensorKind::kSoftBubble, contact, 1);
  const auto frame = Preprocess(rendering.clean, simulator.Reference(SensorKind::kSoftBubble),
                                PreprocessOptions(), 0.015);
  float peak = 0;
  for (float v : frame.values.data) peak = std::fmax(peak, v);
  // Allocated in the library, freed here.
  FrameFormat format;
  format.rows = 20;
  format.cols = 25;
  format.scale = 0.015;
  double sum = 0;
  for (int i = 0; i < 3; ++i) {
    TrunkTargets targets = MakeTrunkTargets(rendering.clean,
                                            simulator.Reference(SensorKind::kSoftBubble),
                                            SensorKind::kSoftBubble, format);
    sum += targets.values.sum();
    sum += Psnr(Eigen::MatrixXf::Zero(targets.values.rows(), targets.values.cols()), targets) > 0;
    // Allocated here (the wrong size), resized by the library.
    LatentModulatedSiren::Options options;
    options.width = 8;
    options.num_hidden_layers = 2;
    options.latent_dim = 4;
    const LatentModulatedSiren siren(options);
    Eigen::MatrixXf outputs = Eigen::MatrixXf::Constant(7, 3, 1.0f);
    Eigen::MatrixXf jacobian = Eigen::MatrixXf::Constant(5, 2, 1.0f);
    siren.ForwardAndLatentJacobian<float>(siren.Grid<float>(4, 5), Eigen::VectorXf::Zero(4),
                                          &outputs, &jacobian);
    sum += (outputs.rows() == 20 && jacobian.rows() == 20 && jacobian.cols() == 4);
  }
  const StepSizeSchedule schedule{StepSizeSchedule::Options()};
  if (!(peak > 0.05f) || !(schedule(0) > 0) || !(sum > 0)) {
    std::printf("consumer: unexpected peak %g\n", peak);
    return 1;
  }
  std::printf("consumer: ok (peak normalised indentation %.3f)\n", peak);
  return 0;
}
