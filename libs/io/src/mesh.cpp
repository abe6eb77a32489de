// OBJ / PLY reading and writing (see rime/io/mesh.h).
