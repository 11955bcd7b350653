# A CellModeller-style model: growth and division at a target volume (2D).
import random

from CellModeller.Biophysics.BacterialModels.CLBacterium import CLBacterium
from CellModeller.Regulation.ModuleRegulator import ModuleRegulator


def setup(sim):
    biophys = CLBacterium(sim, jitter_z=False, max_cells=100000, gamma=10.0)
    regul = ModuleRegulator(sim, sim.moduleName)
    sim.init(biophys, regul, None, None)
    sim.addCell(cellType=0, pos=(0, 0, 0), dir=(1, 0, 0), length=2.0)
    if sim.is_gui:
        from CellModeller.GUI import Renderers
        sim.addRenderer(Renderers.GLBacteriumRenderer(sim))
    sim.pickleSteps = 5


def init(cell):
    cell.targetVol = 2.5 + random.uniform(0.0, 0.5)
    cell.growthRate = 2.0


def update(cells):
    for (id, cell) in cells.items():
        cell.color = [0.1, 0.9, 0.3]
        if cell.volume > cell.targetVol:
            cell.divideFlag = True


def divide(parent, d1, d2):
    d1.targetVol = 2.5 + random.uniform(0.0, 0.5)
    d2.targetVol = 2.5 + random.uniform(0.0, 0.5)
