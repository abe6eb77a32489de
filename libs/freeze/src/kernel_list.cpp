// Compiles the freezing kernel list on the CPU backend (twin: cuda/kernel_list.cu).
#include "rime/freeze/kernels.h"

RIME_FREEZE_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)
