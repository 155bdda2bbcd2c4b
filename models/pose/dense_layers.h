// Copyright 2026 The tactfunc Authors.
//
// The flat-parameter layout of a fully connected network, shared by the pose MLP
// (models/pose/pose_mlp.h) and the pose generator (models/pose/pose_generator.h): layer l
// maps in_l inputs to out_l outputs with a weight matrix (out_l x in_l, column-major) at
// weight_offset followed by its bias (out_l) at bias_offset, layers in order.
#ifndef TACTFUNC_MODELS_POSE_DENSE_LAYERS_H_
#define TACTFUNC_MODELS_POSE_DENSE_LAYERS_H_

#include <vector>

namespace tactfunc {

struct DenseLayer {
  int in = 0, out = 0;
  int weight_offset = 0, bias_offset = 0;
};

// The layers from `inputs` through each of `outputs` (hidden sizes then the output size);
// *num_parameters receives the flat vector's size.
inline std::vector<DenseLayer> DenseLayerLayout(int inputs, const std::vector<int>& outputs,
                                                int* num_parameters) {
  std::vector<DenseLayer> layers;
  int in = inputs, offset = 0;
  for (int out : outputs) {
    DenseLayer layer;
    layer.in = in;
    layer.out = out;
    layer.weight_offset = offset;
    offset += in * out;
    layer.bias_offset = offset;
    offset += out;
    layers.push_back(layer);
    in = out;
  }
  *num_parameters = offset;
  return layers;
}

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_POSE_DENSE_LAYERS_H_
