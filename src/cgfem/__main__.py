from cgfem.cli import console

console()
