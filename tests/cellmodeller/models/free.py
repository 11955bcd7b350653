# One cell growing freely, never dividing: its length after n steps of dt is L (1 + r dt)^n.
from CellModeller.Biophysics.BacterialModels.CLBacterium import CLBacterium
from CellModeller.Regulation.ModuleRegulator import ModuleRegulator


def setup(sim):
    biophys = CLBacterium(sim, jitter_z=False)
    sim.init(biophys, ModuleRegulator(sim), None, None)
    sim.addCell(pos=(0, 0, 0), length=2.0)
    sim.dt = 0.05


def init(cell):
    cell.targetVol = 1e9
    cell.growthRate = 1.0


def update(cells):
    for cell in cells.values():
        cell.seenAge = cell.cellAge
