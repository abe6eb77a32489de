#include "rime/exec/cuda_launch.cuh"
#include "rime/exec/kernels.h"

RIME_EXEC_KERNELS(RIME_INSTANTIATE_CUDA_KERNEL)
