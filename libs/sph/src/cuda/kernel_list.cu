#include "rime/exec/cuda_launch.cuh"
#include "rime/exec/kernel_list.h"
#include "rime/sph/kernels.h"

RIME_SPH_KERNELS(RIME_INSTANTIATE_CUDA_KERNEL)
