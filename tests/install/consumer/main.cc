// Uses one public type from each installed module.
#include <cmath>
#include <cstdio>

#include "estimation/data/preprocess.h"
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
  const StepSizeSchedule schedule{StepSizeSchedule::Options()};
  if (!(peak > 0.05f) || !(schedule(0) > 0)) {
    std::printf("consumer: unexpected peak %g\n", peak);
    return 1;
  }
  std::printf("consumer: ok (peak normalised indentation %.3f)\n", peak);
  return 0;
}
