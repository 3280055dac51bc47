from setuptools import find_packages, setup

package_name = 'awalker_tracker'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['data/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'numba', 'threadpoolctl', 'opencv-python-headless', 'PyYAML'],
    zip_safe=False,
    maintainer='awalker developers',
    maintainer_email='dev@awalker.invalid',
    description='Physics-based 3D person tracking with the Anthropomorphic Walker: ROS-free core and thin rclpy nodes.',
    license='BSD-3-Clause',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'awalker_tracker_node = awalker_tracker.nodes.tracker_node:main',
            'awalker_pose_publisher = awalker_tracker.nodes.pose_publisher_node:main',
            'awalker_features = awalker_tracker.nodes.features_node:main',
        ],
    },
)
