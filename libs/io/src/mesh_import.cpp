// Implemented by the boundary stage work (assimp import).
