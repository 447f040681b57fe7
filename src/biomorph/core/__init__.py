"""Shared maths and data types: transforms, curves, JointSkeleton, BranchGraph, PointCloud."""

from biomorph.core.graph import BranchGraph
from biomorph.core.pointcloud import PointCloud
from biomorph.core.skeleton import JointSkeleton

__all__ = ["BranchGraph", "JointSkeleton", "PointCloud"]
