%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE Cell
    ! cell program: taught on the pendant, edited offline
    PERS tooldata tGripper:=[TRUE,[[0.0,0.0,250.0],[1.000000,0.000000,0.000000,0.000000]],[12.5,[0,0,120],[1,0,0,0],0,0,0]];
    TASK PERS wobjdata wobjTable:=[FALSE,TRUE,"",[[1400.0,-300.0,450.0],[0.923880,0.000000,0.000000,0.382683]],[[0,0,0],[1,0,0,0]]];
    CONST speeddata vFast:=[1500,500,5000,1000];
    VAR robtarget pCurrent;
    CONST num nParts:=4;
    CONST jointtarget j1:=[[98.8209,51.2641,-51.4138,-73.6843,-108.8409,-40.1211],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget p2:=[[-1160.20,2743.56,-145.69],[0.03063788,-0.19010055,0.96282211,0.18946423],[-1,1,-2,6],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget p3:=[[-1324.37,632.49,2190.30],[0.65893227,0.54193211,0.47732895,-0.21041608],[0,-1,-2,4],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget p5:=[[-2355.63,729.26,1923.62],[-0.38013305,0.59174230,0.40960229,-0.58100420],[0,-1,-1,5],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST jointtarget j6:=[[-157.2902,68.0520,-151.9168,118.6548,-32.2371,155.1519],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget p7:=[[-577.26,-1501.52,301.62],[0.61299581,0.57347537,-0.53934720,-0.06683361],[-1,-1,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget p9:=[[-373.49,-784.62,1586.78],[0.95810155,-0.20508723,0.19815715,0.02672817],[-1,1,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget p10:=[[-224.43,1715.27,2349.03],[0.85315184,-0.26097739,0.45114334,0.02219075],[1,1,0,1],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];

    PROC main()
        ConfJ\On;
        ConfL\On;
        MoveAbsJ j1\NoEOffs, vFast, z50, tGripper;
        MoveL Offs(p2,0,0,150), v1000, z50, tGripper\WObj:=wobjTable; ! approach from above
        MoveL p2, v500, z10, tGripper\WObj:=wobjTable;
        SetDO doGripper, 1;
        WaitTime 0.3;
        MoveJ p3, v1000, z10, tGripper\WObj:=wobjTable;
        MoveL [[536.54,1827.51,2143.56],[-0.01291887,-0.46008661,0.33206289,0.82333933],[0,1,-2,2],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]], v200, fine, tGripper\WObj:=wobjTable;
        MoveJ p5, v1000, z10, tGripper\WObj:=wobjTable;
        MoveAbsJ j6\NoEOffs, vFast, z50, tGripper;
        MoveJ p7, v1000, z10, tGripper\WObj:=wobjTable;
        MoveL [[966.85,1362.82,1369.73],[-0.14849794,0.77360253,0.15687293,0.59571669],[0,-2,1,1],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]], v200, fine, tGripper\WObj:=wobjTable;
        MoveJ p9, v1000, z10, tGripper\WObj:=wobjTable;
        MoveL p10, v500, z10, tGripper\WObj:=wobjTable;
        pCurrent:=CRobT(\Tool:=tGripper\WObj:=wobjTable);
        MoveL Offs(pCurrent,0,0,200), v500, z50, tGripper\WObj:=wobjTable;
        WaitTime 0.5;
        TPWrite "cycle done";
    ENDPROC
ENDMODULE
