#include "rime/exec/cuda_launch.cuh"
#include "rime/exec/kernel_list.h"
#include "rime/neighbors/grid_kernels.h"

RIME_NEIGHBORS_KERNELS(RIME_INSTANTIATE_CUDA_KERNEL)
