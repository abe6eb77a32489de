#include "rime/boundary/volume_kernels.h"
#include "rime/exec/cuda_launch.cuh"
#include "rime/exec/kernel_list.h"

RIME_BOUNDARY_KERNELS(RIME_INSTANTIATE_CUDA_KERNEL)
