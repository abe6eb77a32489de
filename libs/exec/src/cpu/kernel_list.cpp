// Compiles the execution layer's kernel list on the CPU backend (the CUDA twin is
// cuda/kernel_list.cu): a kernel added to the list is built for both.
#include "rime/exec/kernels.h"

RIME_EXEC_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)
