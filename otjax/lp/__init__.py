"""Local optimal-transport LPs, shared by every dimension; knows no mesh."""
