#include "rime/exec/cuda_launch.cuh"
#include "rime/exec/kernel_list.h"
#include "rime/freeze/kernels.h"

RIME_FREEZE_KERNELS(RIME_INSTANTIATE_CUDA_KERNEL)
